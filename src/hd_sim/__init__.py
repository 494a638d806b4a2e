"""hd_sim: the plant simulator (EMA + three-body harmonic drive + flap), the data source of the project.

Never imported by twin, onboard, prognostic or ground code. Public API:
``simulate_mission``, ``simulate_fleet``, ``simulate_life``, ``sample_population``,
``nominal``, ``EffectSet``, ``REGISTRY``, ``LAW_SLOTS``, ``FAMILIES``, ``family_unit``, ``make_profile``,
``write_sim_mission``.
See src/hd_sim/README.md.
"""

from .effects import LAW_SLOTS, REGISTRY, EffectSet, effects_table
from .families import FAMILIES, family_unit
from .params import nominal, sample_population


def simulate_mission(*args, **kw):
    """See :func:`hd_sim.plant.simulate_mission` (lazy import: compiles the kernel on first use)."""
    from .plant import simulate_mission as _f

    return _f(*args, **kw)


def simulate_fleet(*args, **kw):
    """See :func:`hd_sim.fleet.simulate_fleet`."""
    from .fleet import simulate_fleet as _f

    return _f(*args, **kw)


def simulate_life(*args, **kw):
    """See :func:`hd_sim.fleet.simulate_life`."""
    from .fleet import simulate_life as _f

    return _f(*args, **kw)


def make_profile(*args, **kw):
    """See :func:`hd_sim.profiles.make_profile`."""
    from .profiles import make_profile as _f

    return _f(*args, **kw)


def write_sim_mission(path, params=None, effects=None, profile="inspection", seed=0, *, with_sim=True, **kw):
    """Simulate one mission and write it as a contract bag at ``path``; returns (path, Mission, truth)."""
    from hd_bag import write_mission

    m, truth = simulate_mission(params, effects, profile, seed, **kw)
    write_mission(path, m, sim=truth if with_sim else None)
    return str(path), m, truth


__all__ = ["LAW_SLOTS", "FAMILIES", "family_unit", "REGISTRY", "EffectSet", "effects_table", "nominal", "sample_population", "simulate_mission",
           "simulate_fleet", "simulate_life", "make_profile", "write_sim_mission"]
