"""Every way to run something, each a straight sequence of steps (load → resolve world and
vessel → build → simulate → measure → write):

- :mod:`~usvdrake.run.mission`: one vessel's scenario (``usvdrake run``);
- :mod:`~usvdrake.run.fleet`: a fleet of taxis (scenarios with ``controller: taxi``);
- :mod:`~usvdrake.run.hil`: the hardware diagram against emulated or real devices;
- :mod:`~usvdrake.run.campaign`: Monte Carlo over random days on Dask;
- :mod:`~usvdrake.run.encounter`: DNV traffic situations, one or a set on Dask
  (``usvdrake encounter``, ``usvdrake encounters``);
- :mod:`~usvdrake.run.slam2d` and :mod:`~usvdrake.run.slam3d`: SLAM offline on recordings.

They share one simulation loop, :func:`usvdrake.run.simulate.simulate`.
"""
