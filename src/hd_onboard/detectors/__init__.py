"""Residual detectors of the onboard core, one module per detector.

* :mod:`.levels`: fault levels (OK/WARN/ERROR/STALE), persistence runs, the hold latch;
* :mod:`.ewma`: per-channel lines (:class:`~.ewma.ChannelThreshold`) and the EWMA detector;
* :mod:`.regression`: exponentially weighted regression moments shared by the two monitors;
* :mod:`.stiffness`: torsional-stiffness reference law and monitor;
* :mod:`.friction`: friction (lubrication) reference and monitor.
"""
