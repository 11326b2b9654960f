"""Availability of trusted satellites along a line, interval prediction and the report.

* :mod:`predisat.availability.satellites` - constellations, positions, azimuth/elevation, trust.
* :mod:`predisat.availability.engine` - counts of trusted satellites per position and epoch.
* :mod:`predisat.availability.interval` - predicted SATHIA interval lengths.
* :mod:`predisat.availability.trainrun` - the satellites a running train may trust.
* :mod:`predisat.availability.report`, :mod:`predisat.availability.plots` - the HTML report.
* :mod:`predisat.availability.run` - the whole ``predisat availability`` job.
"""
