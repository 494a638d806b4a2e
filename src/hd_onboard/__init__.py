"""Onboard data manipulation and state detection: one module per concept (docs/ARCHITECTURE.md,
"Onboard modules"). :class:`hd_onboard.core.OnboardCore` orchestrates them; :func:`hd_onboard.batch.run_mission`
drives a whole mission through it."""
