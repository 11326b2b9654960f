"""GNSS: time scales, navigation and orbit files, satellite positions and clocks, error model.

* :mod:`predisat.gnss.timescale` - GPS seconds, UTC and leap seconds, BeiDou and GLONASS time.
* :mod:`predisat.gnss.rinex_nav`, :mod:`predisat.gnss.sp3`, :mod:`predisat.gnss.tle` - readers.
* :mod:`predisat.gnss.orbits` - broadcast orbits (Kepler and GLONASS).
* :mod:`predisat.gnss.ephemeris` - one facade over broadcast, precise and TLE orbits.
* :mod:`predisat.gnss.antenna_offsets` - satellite antenna phase-centre offsets.
* :mod:`predisat.gnss.sun` - the solar position (satellite attitude, rendered skies).
* :mod:`predisat.gnss.errormodel` - the pseudorange error model ``sigma(el)`` shared with the
  locator, the pair-interval width, error-model files.
"""
