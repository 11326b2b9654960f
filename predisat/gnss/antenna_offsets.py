"""Satellite antenna phase-centre offsets: from antenna phase centre (APC) to centre of mass (CoM).

Broadcast ephemerides give the position of the transmitting antenna's phase centre; precise
orbits (SP3) give the satellite's centre of mass. The two differ by the phase-centre offset
(PCO), a body-fixed vector of 0.6 to 2.7 m, mostly along the axis that points at the Earth. This
module holds the PCOs of the IGS ANTEX conventions per satellite block, the PRN -> SVN -> block
assignment over time, and the vector geometry of the nominal attitude:

* body frame (IGS ANTEX convention): ``z`` from the satellite toward the Earth's centre, ``y``
  along ``z x (sun direction)`` (the solar-panel axis), ``x = y x z`` completing the right-handed
  triad, so that ``x`` points toward the sun-lit half-space (nominal yaw steering; the noon and
  midnight turns and eclipse manoeuvres are not modelled: they only rotate ``x``/``y``, a few
  decimetres at most);
* ``APC = CoM + x_pco e_x + y_pco e_y + z_pco e_z``, hence :func:`com_from_apc`.

Offset values (ionosphere-free combination, metres, body frame)
----------------------------------------------------------------
Block values, not per-satellite ones: individual satellites of one block differ by up to
+-0.2 m in ``z`` (GPS IIA 2.28-2.68 m in igs05), well under the metre-level accuracy of broadcast
orbits. Sources, each cited in :data:`PCO_SOURCES`:

* GPS IIA, IIR-A, IIR-B, IIR-M, IIF and first-generation GLONASS: IGS ``igs05_1627.atx`` as
  shipped by RTKLIB (``tomojitakasu/RTKLIB``, ``data/igs05.atx``; the model of the IGS final
  orbits of 2009-2011), means of the satellite-specific ``NORTH / EAST / UP`` records;
* GLONASS-M: the block value the IGS assigns to every new GLONASS-M satellite in ``igs14.atx``
  (IGSMAIL announcements of igs14_2013.atx and igs14_2101.atx: X -54.5 cm, Y 0, Z 245.0 cm;
  igs05 used Z 230.0 cm);
* Galileo IOV (GALILEO-1) and FOC (GALILEO-2): the conventional MGEX values of
  ``igs08_1915.atx`` (IGSMAIL-7356, rounded means of DLR and GFZ estimates; FOC E201/E202 in
  eccentric orbits differ by 5 cm in z, ignored).

No value is given (NaN) for blocks whose published offsets were not at hand: GPS IIIA,
GLONASS-K1/K2, BeiDou, QZSS, IRNSS.

Caveat on what the broadcast orbit refers to: a broadcast orbit refers to the antenna offsets
its control segment uses. The GLONASS, Galileo and (in 2021 and 2023) GPS broadcast orbits agree
with these values to 0.3 m in the mean radial; the GPS broadcast orbits of 2010 do not (raw
radial differences of -0.9 m for IIA, -1.6 m for IIR-A and 0.0 m for IIR-B/IIR-M satellites,
against igs05 offsets of 2.45, 1.15 and 0.7 m): the control segment then still used its own
offsets (IIA 1.023 m and IIR 0 m in the convention the IGS recorded in 1998).
``scripts/eval_orbits.py`` measures this per block; see ``docs/ephemerides.md``.

PRN -> SVN -> block
-------------------
:data:`SVN_TABLE` lists, for GPS and GLONASS since 2009 and for Galileo, which space vehicle
(SVN) transmitted each PRN and when, transcribed from PRIDE PPP-AR ``table/sat_parameters``
(``PrideLab/PRIDE-PPPAR``, generated 2024-02-07 from the IGS satellite metadata; day precision;
short gaps between stints of the same vehicle merged).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.gnss.sun import sun_azel
from predisat.gnss.timescale import datetime64_to_gps_s

__all__ = [
    "BLOCK_PCO_M",
    "PCO_SOURCES",
    "SVN_TABLE",
    "block_pco_m",
    "body_axes_ecef",
    "com_from_apc",
    "satellite_block",
    "sun_direction_ecef",
]

_IGS05 = "igs05_1627.atx (RTKLIB data/igs05.atx)"
PCO_SOURCES: Mapping[str, str] = {
    "BLOCK IIA": f"{_IGS05}: x 279 mm; z mean of the 11 SVNs active in 2010 (2279-2676 mm)",
    "BLOCK IIR-A": f"{_IGS05}: z mean of 8 SVNs G041 G043 G044 G045 G046 G051 G054 G056 "
    "(911-1307 mm)",
    "BLOCK IIR-B": f"{_IGS05}: z mean of G047 G059 G060 G061 (602-792 mm)",
    "BLOCK IIR-M": f"{_IGS05}: preliminary IIR-M value 700 mm (G053 645, G052 750)",
    "BLOCK IIF": f"{_IGS05}: G062, x 394 mm, z 1407 mm (update of GPS week 1602)",
    "GLONASS": f"{_IGS05}: z mean of R789 R794 R795 R796 (1944-2006 mm)",
    "GLONASS-M": "igs14.atx block value for new GLONASS-M (IGSMAIL igs14_2013/igs14_2101: "
    "X -54.5 cm, Y 0, Z 245.0 cm)",
    "GALILEO-1": "igs08_1915.atx conventional MGEX value (IGSMAIL-7356): -17/+3/+95 cm",
    "GALILEO-2": "igs08_1915.atx conventional MGEX value (IGSMAIL-7356): +12/-1/+110 cm",
}
"""Where each value of :data:`BLOCK_PCO_M` comes from."""

BLOCK_PCO_M: Mapping[str, tuple[float, float, float]] = {
    "BLOCK IIA": (0.279, 0.0, 2.453),
    "BLOCK IIR-A": (0.0, 0.0, 1.145),
    "BLOCK IIR-B": (0.0, 0.0, 0.669),
    "BLOCK IIR-M": (0.0, 0.0, 0.700),
    "BLOCK IIF": (0.394, 0.0, 1.407),
    "GLONASS": (0.0, 0.0, 1.978),
    "GLONASS-M": (-0.545, 0.0, 2.450),
    "GALILEO-1": (-0.17, 0.03, 0.95),
    "GALILEO-2": (0.12, -0.01, 1.10),
}
"""Ionosphere-free PCO ``(x, y, z)`` in metres in the IGS body frame, per ANTEX block name."""

_IIA, _RA, _RB, _RM = "BLOCK IIA", "BLOCK IIR-A", "BLOCK IIR-B", "BLOCK IIR-M"
_IIF, _III = "BLOCK IIF", "BLOCK IIIA"
_R, _RMM, _K1, _K2 = "GLONASS", "GLONASS-M", "GLONASS-K1", "GLONASS-K2"
_E1, _E2 = "GALILEO-1", "GALILEO-2"

SVN_TABLE: tuple[tuple[str, str, str, int, int | None], ...] = (
    # (PRN, SVN, ANTEX block, first day YYYYDDD, last day YYYYDDD or None = still active)
    ("G01", "G049", _RM, 2009083, 2011126), ("G01", "G035", _IIA, 2011153, 2011193),
    ("G01", "G063", _IIF, 2011197, None),
    ("G02", "G061", _RB, 2004311, None),
    ("G03", "G033", _IIA, 1996088, 2014230), ("G03", "G035", _IIA, 2014248, 2014293),
    ("G03", "G069", _IIF, 2014302, None),
    ("G04", "G034", _IIA, 1993299, 2015313), ("G04", "G049", _RM, 2016033, 2016257),
    ("G04", "G032", _IIA, 2016259, 2016340), ("G04", "G034", _IIA, 2016344, 2017003),
    ("G04", "G049", _RM, 2017006, 2017132), ("G04", "G038", _IIA, 2017139, 2017195),
    ("G04", "G036", _IIA, 2017201, 2017332), ("G04", "G049", _RM, 2017335, 2018271),
    ("G04", "G036", _IIA, 2018283, 2019002), ("G04", "G074", _III, 2019009, 2019193),
    ("G04", "G036", _IIA, 2019194, 2019281), ("G04", "G074", _III, 2019294, None),
    ("G05", "G035", _IIA, 1993242, 2009159), ("G05", "G050", _RM, 2009229, None),
    ("G06", "G036", _IIA, 1994069, 2014062), ("G06", "G049", _RM, 2014093, 2014125),
    ("G06", "G067", _IIF, 2014137, None),
    ("G07", "G048", _RM, 2008075, None),
    ("G08", "G038", _IIA, 1997310, 2015103), ("G08", "G049", _RM, 2015120, 2015182),
    ("G08", "G072", _IIF, 2015196, None),
    ("G09", "G039", _IIA, 1993177, 2014202), ("G09", "G068", _IIF, 2014214, None),
    ("G10", "G040", _IIA, 1996198, 2015215), ("G10", "G036", _IIA, 2015259, 2015299),
    ("G10", "G073", _IIF, 2015304, None),
    ("G11", "G046", _RA, 1999280, 2021099), ("G11", "G078", _III, 2021168, None),
    ("G12", "G058", _RM, 2006321, None),
    ("G13", "G043", _RA, 1997204, None),
    ("G14", "G041", _RA, 2000315, 2020209), ("G14", "G077", _III, 2020310, None),
    ("G15", "G055", _RM, 2007290, None),
    ("G16", "G056", _RA, 2003029, None),
    ("G17", "G053", _RM, 2005269, None),
    ("G18", "G054", _RA, 2001030, 2018023), ("G18", "G034", _IIA, 2018024, 2020069),
    ("G18", "G075", _III, 2020073, None),
    ("G19", "G059", _RB, 2004080, None),
    ("G20", "G051", _RA, 2000132, None),
    ("G21", "G045", _RA, 2003090, None),
    ("G22", "G047", _RB, 2003355, 2022018), ("G22", "G041", _RA, 2022020, 2023219),
    ("G22", "G044", _RA, 2023222, None),
    ("G23", "G060", _RB, 2004175, 2020161), ("G23", "G076", _III, 2020196, None),
    ("G24", "G024", _IIA, 1991185, 2011273), ("G24", "G049", _RM, 2012033, 2012074),
    ("G24", "G032", _IIA, 2012075, 2012116), ("G24", "G037", _IIA, 2012117, 2012151),
    ("G24", "G049", _RM, 2012222, 2012235), ("G24", "G065", _IIF, 2012278, None),
    ("G25", "G025", _IIA, 1992054, 2010039), ("G25", "G035", _IIA, 2010040, 2010147),
    ("G25", "G062", _IIF, 2010148, None),
    ("G26", "G026", _IIA, 1992189, 2015005), ("G26", "G032", _IIA, 2015036, 2015055),
    ("G26", "G027", _IIA, 2015058, 2015075), ("G26", "G071", _IIF, 2015084, None),
    ("G27", "G027", _IIA, 1992253, 2012291), ("G27", "G049", _RM, 2012292, 2013129),
    ("G27", "G066", _IIF, 2013135, None),
    ("G28", "G044", _RA, 2000198, 2022298), ("G28", "G049", _RM, 2022299, 2022306),
    ("G28", "G079", _III, 2023031, None),
    ("G29", "G057", _RM, 2007354, None),
    ("G30", "G030", _IIA, 1996256, 2011216), ("G30", "G035", _IIA, 2011217, 2013126),
    ("G30", "G049", _RM, 2013130, 2013233), ("G30", "G032", _IIA, 2013234, 2013259),
    ("G30", "G037", _IIA, 2013262, 2013280), ("G30", "G027", _IIA, 2013337, 2013351),
    ("G30", "G049", _RM, 2013353, 2014041), ("G30", "G064", _IIF, 2014052, None),
    ("G31", "G052", _RM, 2006268, None),
    ("G32", "G023", _IIA, 2006336, 2016025), ("G32", "G070", _IIF, 2016036, None),
    ("R01", "R796", _R, 2004361, 2009347), ("R01", "R730", _RMM, 2009348, None),
    ("R02", "R728", _RMM, 2008360, 2013181), ("R02", "R747", _RMM, 2013182, None),
    ("R03", "R727", _RMM, 2008360, 2010273), ("R03", "R722", _RMM, 2010274, 2010349),
    ("R03", "R727", _RMM, 2010350, 2011069), ("R03", "R715", _RMM, 2011070, 2011285),
    ("R03", "R801", _K1, 2011286, 2011334), ("R03", "R744", _RMM, 2011335, None),
    ("R04", "R795", _R, 2003344, 2009347), ("R04", "R733", _RMM, 2009348, 2010273),
    ("R04", "R727", _RMM, 2010274, 2010349), ("R04", "R801", _K1, 2011057, 2011284),
    ("R04", "R742", _RMM, 2011286, 2019237), ("R04", "R859", _RMM, 2019361, None),
    ("R05", "R711", _R, 2001335, 2009347), ("R05", "R734", _RMM, 2009348, 2018224),
    ("R05", "R856", _RMM, 2018234, None),
    ("R06", "R701", _RMM, 2003344, 2010117), ("R06", "R714", _RMM, 2010118, 2010273),
    ("R06", "R733", _RMM, 2010274, None),
    ("R07", "R712", _RMM, 2004361, 2011348), ("R07", "R745", _RMM, 2011349, None),
    ("R08", "R729", _RMM, 2008360, 2012257), ("R08", "R743", _RMM, 2012261, 2012291),
    ("R08", "R712", _RMM, 2012292, 2012356), ("R08", "R743", _RMM, 2012357, 2013005),
    ("R08", "R801", _K1, 2013006, 2013053), ("R08", "R743", _RMM, 2013054, None),
    ("R09", "R722", _RMM, 2007359, 2010273), ("R09", "R736", _RMM, 2010274, 2016046),
    ("R09", "R802", _K1, 2016047, None),
    ("R10", "R717", _RMM, 2006359, 2019214), ("R10", "R723", _RMM, 2019273, None),
    ("R11", "R723", _RMM, 2007359, 2016175), ("R11", "R853", _RMM, 2016176, 2020335),
    ("R11", "R805", _K1, 2020336, None),
    ("R12", "R767", _R, 1996001, 2010244), ("R12", "R737", _RMM, 2010245, 2016327),
    ("R12", "R723", _RMM, 2016350, 2019169), ("R12", "R858", _RMM, 2019170, None),
    ("R13", "R721", _RMM, 2007359, None),
    ("R14", "R715", _RMM, 2006359, 2010349), ("R14", "R722", _RMM, 2010350, 2011285),
    ("R14", "R715", _RMM, 2011286, 2017189), ("R14", "R801", _K1, 2017264, 2017278),
    ("R14", "R852", _RMM, 2017283, None),
    ("R15", "R716", _RMM, 2006359, 2018327), ("R15", "R857", _RMM, 2018328, None),
    ("R16", "R775", _R, 1996001, 2010244), ("R16", "R736", _RMM, 2010245, 2010273),
    ("R16", "R738", _RMM, 2010274, 2016045), ("R16", "R736", _RMM, 2016069, 2021347),
    ("R16", "R861", _RMM, 2022354, None),
    ("R17", "R718", _RMM, 2007299, 2010349), ("R17", "R714", _RMM, 2010350, 2011353),
    ("R17", "R746", _RMM, 2011354, 2015102), ("R17", "R714", _RMM, 2015103, 2016026),
    ("R17", "R802", _K1, 2016027, 2016046), ("R17", "R714", _RMM, 2016047, 2016054),
    ("R17", "R851", _RMM, 2016055, None),
    ("R18", "R724", _RMM, 2008269, 2014042), ("R18", "R714", _RMM, 2014049, 2014100),
    ("R18", "R854", _RMM, 2014101, None),
    ("R19", "R720", _RMM, 2007299, None),
    ("R20", "R719", _RMM, 2007299, None),
    ("R21", "R725", _RMM, 2008269, 2014213), ("R21", "R855", _RMM, 2014214, None),
    ("R22", "R726", _RMM, 2008269, 2010059), ("R22", "R731", _RMM, 2010060, 2020176),
    ("R22", "R735", _RMM, 2020226, 2022155), ("R22", "R806", _K1, 2022281, None),
    ("R23", "R714", _RMM, 2006059, 2010077), ("R23", "R732", _RMM, 2010078, None),
    ("R24", "R713", _RMM, 2005359, 2010059), ("R24", "R735", _RMM, 2010060, 2020100),
    ("R24", "R860", _RMM, 2020101, None),
    ("R25", "R805", _K1, 2020317, 2020335), ("R25", "R805", _K1, 2022219, 2022280),
    ("R25", "R807", _K1, 2022310, None),
    ("R26", "R801", _K1, 2012075, 2013005), ("R26", "R801", _K1, 2013054, 2017263),
    ("R26", "R801", _K1, 2017279, 2021337), ("R26", "R801", _K1, 2022279, 2023002),
    ("R26", "R803", _K2, 2023252, None),
    ("R27", "R802", _K1, 2014334, 2016026), ("R27", "R716", _RMM, 2019215, 2021337),
    ("E01", "E210", _E2, 2016145, None), ("E02", "E211", _E2, 2016145, None),
    ("E03", "E212", _E2, 2016322, None), ("E04", "E213", _E2, 2016322, None),
    ("E05", "E214", _E2, 2016322, None), ("E07", "E207", _E2, 2016322, None),
    ("E08", "E208", _E2, 2015351, None), ("E09", "E209", _E2, 2015351, None),
    ("E10", "E224", _E2, 2021339, None), ("E11", "E101", _E1, 2011294, None),
    ("E12", "E102", _E1, 2011294, None), ("E13", "E220", _E2, 2018206, None),
    ("E14", "E202", _E2, 2014234, None), ("E15", "E221", _E2, 2018206, None),
    ("E18", "E201", _E2, 2014234, None), ("E19", "E103", _E1, 2012286, None),
    ("E20", "E104", _E1, 2012286, None), ("E21", "E215", _E2, 2017346, None),
    ("E22", "E204", _E2, 2015086, None), ("E24", "E205", _E2, 2015254, None),
    ("E25", "E216", _E2, 2017346, None), ("E26", "E203", _E2, 2015086, None),
    ("E27", "E217", _E2, 2017346, None), ("E30", "E206", _E2, 2015254, None),
    ("E31", "E218", _E2, 2017346, None), ("E33", "E222", _E2, 2018206, None),
    ("E34", "E223", _E2, 2021339, None), ("E36", "E219", _E2, 2018206, None),
)  # fmt: skip
"""Which vehicle (SVN) and ANTEX block transmitted each PRN, by day (see the module notes)."""


def _day_start_gps_s(yyyyddd: int) -> float:
    year, doy = divmod(yyyyddd, 1000)
    day = np.datetime64(f"{year:04d}-01-01") + np.timedelta64(doy - 1, "D")
    return float(datetime64_to_gps_s(day))


# (prn, block, first_gps_s, end_gps_s exclusive); the table's days are whole days
_INTERVALS = tuple(
    (
        prn,
        block,
        _day_start_gps_s(first),
        np.inf if last is None else _day_start_gps_s(last) + 86400.0,
    )
    for prn, _svn, block, first, last in SVN_TABLE
)


def satellite_block(sats: Sequence[str], gps_s: ArrayLike) -> NDArray:
    """ANTEX block name of each satellite at each epoch.

    Parameters
    ----------
    sats : sequence of str, length n_sat
        Satellite ids (``"G05"``, ``"R07"``, ``"E11"``).
    gps_s : array_like, shape (n_epoch,)
        GPS time in seconds.

    Returns
    -------
    ndarray of str, shape (n_epoch, n_sat)
        Block names as in :data:`SVN_TABLE` (``"BLOCK IIF"``, ``"GLONASS-M"``, ...); ``""`` where
        the table does not know the satellite at that epoch.
    """
    t = np.atleast_1d(np.asarray(gps_s, float))
    if t.ndim != 1:
        raise ValueError(f"gps_s must be a scalar or 1-D, got shape {t.shape}")
    out = np.full((len(t), len(sats)), "", dtype="<U16")
    for j, sat in enumerate(sats):
        for prn, block, first, end in _INTERVALS:
            if prn == sat:
                out[(t >= first) & (t < end), j] = block
    return out


def block_pco_m(blocks: ArrayLike) -> NDArray:
    """Phase-centre offsets in the satellite body frame for block names.

    Parameters
    ----------
    blocks : array_like of str, shape (...)
        ANTEX block names (as returned by :func:`satellite_block`).

    Returns
    -------
    ndarray, shape (..., 3)
        ``(x, y, z)`` PCO in metres (ionosphere-free, IGS body frame); NaN for blocks without a
        value in :data:`BLOCK_PCO_M` (unknown satellites, GPS IIIA, GLONASS-K, BeiDou, ...).
    """
    b = np.asarray(blocks, dtype=str)
    out = np.full((*b.shape, 3), np.nan)
    for name, pco in BLOCK_PCO_M.items():
        out[b == name] = pco
    return out


def body_axes_ecef(pos_ecef_m: ArrayLike, sun_dir_ecef: ArrayLike) -> NDArray:
    """Unit axes of the nominal (yaw-steering) satellite body frame, in ECEF.

    Parameters
    ----------
    pos_ecef_m : array_like, shape (..., 3)
        Satellite positions in metres.
    sun_dir_ecef : array_like, shape (..., 3)
        Direction of the sun from the Earth's centre (any length; normalised here), broadcast
        with ``pos_ecef_m``. Using the geocentric instead of the satellite's own sun direction
        tilts ``x`` by under ``|r| / 1 au`` = 0.01 deg (0.1 mm on a 0.5 m offset).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Rows ``e_x``, ``e_y``, ``e_z``: ``e_z`` toward the Earth's centre, ``e_y = e_z x e_sun``
        normalised, ``e_x = e_y x e_z`` (toward the sun side). Where the sun is within 1e-9 rad
        of the ``z`` axis (exact noon/midnight), ``e_x`` and ``e_y`` are NaN.
    """
    r = np.asarray(pos_ecef_m, float)
    s = np.asarray(sun_dir_ecef, float)
    if r.shape[-1:] != (3,) or s.shape[-1:] != (3,):
        raise ValueError(
            f"pos_ecef_m and sun_dir_ecef need a last axis of 3, got {r.shape} and {s.shape}"
        )
    r_norm = np.linalg.norm(r, axis=-1, keepdims=True)
    s_norm = np.linalg.norm(s, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        ez = -r / r_norm
        ey = np.cross(ez, s / s_norm)
        ey_norm = np.linalg.norm(ey, axis=-1, keepdims=True)
        ey = np.where(ey_norm > 1e-9, ey / ey_norm, np.nan)
    ex = np.cross(ey, ez)
    ez = np.broadcast_to(ez, ex.shape)
    return np.stack([ex, ey, ez], axis=-2)


def com_from_apc(pos_apc_ecef_m: ArrayLike, pco_m: ArrayLike, sun_dir_ecef: ArrayLike) -> NDArray:
    """Centre-of-mass positions from antenna phase-centre positions.

    Parameters
    ----------
    pos_apc_ecef_m : array_like, shape (..., 3)
        Antenna phase-centre positions (e.g. from broadcast ephemerides), metres.
    pco_m : array_like, shape (..., 3)
        Body-frame PCO ``(x, y, z)`` in metres (:func:`block_pco_m`), broadcast with the
        positions. A PCO with ``x = y = 0`` needs no sun: pass any non-zero direction.
    sun_dir_ecef : array_like, shape (..., 3)
        Geocentric sun direction (:func:`sun_direction_ecef`), broadcast with the positions.

    Returns
    -------
    ndarray, shape (..., 3)
        ``APC - R^T pco``; NaN where the position or the PCO is NaN, and where the attitude is
        undefined (see :func:`body_axes_ecef`) for offsets with an ``x``/``y`` part.
    """
    r = np.asarray(pos_apc_ecef_m, float)
    pco = np.asarray(pco_m, float)
    if pco.shape[-1:] != (3,):
        raise ValueError(f"pco_m needs a last axis of 3 (x, y, z), got shape {pco.shape}")
    axes = body_axes_ecef(r, sun_dir_ecef)
    # a zero x/y offset contributes nothing even where the x/y axes are undefined
    xy = np.where(pco[..., :2, None] == 0.0, 0.0, pco[..., :2, None] * axes[..., :2, :])
    offset = xy.sum(axis=-2) + pco[..., 2:3] * axes[..., 2, :]
    return r - offset


def sun_direction_ecef(gps_s: ArrayLike) -> NDArray:
    """Geocentric unit direction of the sun in ECEF (low precision, about 0.01 deg).

    Uses :func:`predisat.gnss.sun.sun_azel` (NOAA/Meeus) seen from latitude 0, longitude 0,
    where east, north and up are the ECEF y, z and x axes; that function ignores the solar
    parallax, so the direction is the geocentric one.

    Parameters
    ----------
    gps_s : array_like, shape (...)
        GPS time in seconds.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    t = np.asarray(gps_s, float)
    az_deg, el_deg = sun_azel(t, np.zeros_like(t), np.zeros_like(t), refraction=False)
    az, el = np.radians(az_deg), np.radians(el_deg)
    east, north, up = np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)
    return np.stack([up, east, north], axis=-1)
