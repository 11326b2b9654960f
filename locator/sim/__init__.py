"""The pseudorange simulator: a train run through a synthetic world, with ground truth.

* :mod:`locator.sim.simulate` - :func:`simulate_run`: LOS, multipath, NLOS and loss.
* :mod:`locator.sim.multipath` - single-bounce reflections, signal strength, code multipath.
* :mod:`locator.sim.simfile` - :class:`SimRun` and its file format (``locator.simrun/1``).
"""
