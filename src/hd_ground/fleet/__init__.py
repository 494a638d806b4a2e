"""Fleet-scale ground analytics on Dask: per-mission and per-actuator tasks, a Parquet + DuckDB store,
fault classification across missions. See docs/FLEET.md.

* :mod:`hd_ground.fleet.tasks`: the tasks (pure functions of bag paths; run on Dask workers);
* :mod:`hd_ground.fleet.store`: the partitioned Parquet store and its DuckDB views;
* :mod:`hd_ground.fleet.classify`: Gaussian class-conditional fault classifier with an "unknown" class;
* :mod:`hd_ground.fleet.run`: the driver (``hdphm ground fleet``) and ``fleet status``.
"""
