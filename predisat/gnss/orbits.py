"""Satellite positions and clocks from broadcast ephemerides.

Two orbit families, both vectorised over any number of (record, epoch) pairs:

* Keplerian elements with harmonic corrections (GPS IS-GPS-200, Galileo OS SIS ICD, BeiDou
  B1I ICD incl. the GEO rotation, QZSS IS-QZSS, IRNSS ICD), and the GPS/QZSS CNAV elements
  with their semi-major axis rate and mean-motion rate (IS-GPS-200 30.3.3.1): :func:`kepler_state`;
* GLONASS (ICD 5.1, appendix A.3.1.2): the broadcast position and velocity at tb are integrated
  with 4th-order Runge-Kutta in the rotating PZ-90 frame, with the central term, the J2
  oblateness term and the broadcast (constant) lunisolar accelerations:
  :func:`glonass_state`.

Positions are ECEF metres (WGS84/ITRF for GPS; the other systems' frames agree with it to a few
centimetres, except PZ-90.02 before 2014, which is within half a metre), clocks are the
satellite clock offset in seconds, including the relativistic correction for Keplerian orbits,
without group delays (the reference of the broadcast af0, i.e. the dual-frequency combination
of each system, the same reference as precise clock products).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.gnss.rinex_nav import NavRecords

__all__ = [
    "BEIDOU_GEO_PRNS",
    "C_MPS",
    "GLONASS_CONSTANTS",
    "KEPLER_CONSTANTS",
    "glonass_state",
    "kepler_state",
]

C_MPS = 299792458.0

# (mu m^3/s^2, Earth rotation rad/s) per system, from the ICDs
KEPLER_CONSTANTS: dict[str, tuple[float, float]] = {
    "G": (3.9860050e14, 7.2921151467e-5),
    "J": (3.9860050e14, 7.2921151467e-5),
    "I": (3.9860050e14, 7.2921151467e-5),
    "E": (3.986004418e14, 7.2921151467e-5),
    "C": (3.986004418e14, 7.2921150e-5),
}

BEIDOU_GEO_PRNS = frozenset((1, 2, 3, 4, 5, 59, 60, 61, 62, 63))
"""BeiDou PRNs of geostationary satellites, whose broadcast orbit is rotated (BDS ICD 5.2.4.12)."""

GLONASS_CONSTANTS = {
    "mu_m3ps2": 398600.4418e9,
    "ae_m": 6378136.0,
    "j2": 1082625.75e-9,
    "omega_radps": 7.292115e-5,
}


def _gather(rec: NavRecords, idx: NDArray, name: str) -> NDArray:
    return rec.values[idx, rec.fields.index(name)]


def kepler_state(
    rec: NavRecords, idx: ArrayLike, gps_s: ArrayLike, n_iter: int = 10
) -> tuple[NDArray, NDArray]:
    """Positions and clock offsets from Keplerian broadcast records.

    Parameters
    ----------
    rec : NavRecords
        Keplerian records (``rec.kind == "kepler"``).
    idx : array_like of int, shape (m,)
        Record to use for each evaluation.
    gps_s : array_like, shape (m,)
        Evaluation times (GPST seconds; the signal transmission time for ranging).
    n_iter : int
        Newton iterations for Kepler's equation (10 reach 1e-15 rad for e < 0.1).

    Returns
    -------
    pos_ecef_m : ndarray, shape (m, 3)
        ECEF position at ``gps_s`` in the Earth-fixed frame of that same instant.
    clock_s : ndarray, shape (m,)
        af0 + af1 dt + af2 dt^2 + relativistic correction; no group delay.
    """
    if rec.kind != "kepler":
        raise ValueError(f"kepler_state needs Keplerian records, got kind={rec.kind!r}")
    idx = np.asarray(idx, np.intp)
    t = np.asarray(gps_s, float)
    # per-record properties first (n records), then gathered (m evaluations)
    rec_system = rec.sat.astype("<U1")
    system = rec_system[idx]
    mu = np.empty(len(idx))
    we = np.empty(len(idx))
    for letter, (m, w) in KEPLER_CONSTANTS.items():
        sel = system == letter
        mu[sel], we[sel] = m, w

    def g(name: str) -> NDArray:
        return _gather(rec, idx, name)

    sqrt_a = g("sqrt_a_sqrtm")
    a = sqrt_a**2
    e = g("e")
    tk = t - rec.ref_gps_s[idx]
    n = np.sqrt(mu / a**3) + g("delta_n_radps")
    cnav = g("cnav") == 1.0 if "cnav" in rec.fields else np.zeros(len(idx), bool)
    if np.any(cnav):
        # GPS/QZSS CNAV (IS-GPS-200 Table 30-II): A_k = A0 + Adot tk in the radius, and the
        # mean motion n_A = n0 + dn0 + dn0dot tk / 2 (n0 from A0); legacy rows untouched
        n = np.where(cnav, n + 0.5 * g("delta_n_dot_radps2") * tk, n)
        a_k = np.where(cnav, a + g("adot_mps") * tk, a)
    else:
        a_k = a
    mk = g("m0_rad") + n * tk
    ek = mk.copy()
    for _ in range(n_iter):
        ek = ek - (ek - e * np.sin(ek) - mk) / (1.0 - e * np.cos(ek))
    sin_e, cos_e = np.sin(ek), np.cos(ek)
    nu = np.arctan2(np.sqrt(1.0 - e**2) * sin_e, cos_e - e)
    phi = nu + g("omega_rad")
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    u = phi + g("cus_rad") * s2 + g("cuc_rad") * c2
    r = a_k * (1.0 - e * cos_e) + g("crs_m") * s2 + g("crc_m") * c2
    inc = g("i0_rad") + g("cis_rad") * s2 + g("cic_rad") * c2 + g("idot_radps") * tk
    xp, yp = r * np.cos(u), r * np.sin(u)
    toe_sow = g("toe_sow_s")
    geo_ids = {f"C{p:02d}" for p in BEIDOU_GEO_PRNS}
    geo = np.isin(rec.sat, list(geo_ids))[idx]
    # GEO: the node is not corrected for Earth rotation here but by the final rotation
    big_omega = g("omega0_rad") + (g("omega_dot_radps") - np.where(geo, 0.0, we)) * tk
    big_omega = big_omega - we * toe_sow
    co, so, ci, si = np.cos(big_omega), np.sin(big_omega), np.cos(inc), np.sin(inc)
    x = xp * co - yp * ci * so
    y = xp * so + yp * ci * co
    z = yp * si
    if np.any(geo):
        phx = np.radians(-5.0)
        phz = we[geo] * tk[geo]
        xg, yg, zg = x[geo], y[geo], z[geo]
        # R_X(-5 deg) then R_Z(we tk), as in the BDS ICD
        y1 = np.cos(phx) * yg + np.sin(phx) * zg
        z1 = -np.sin(phx) * yg + np.cos(phx) * zg
        x[geo] = np.cos(phz) * xg + np.sin(phz) * y1
        y[geo] = -np.sin(phz) * xg + np.cos(phz) * y1
        z[geo] = z1
    dt = t - rec.epoch_gps_s[idx]
    f_rel = -2.0 * np.sqrt(mu) / C_MPS**2
    clock = g("af0_s") + g("af1_sps") * dt + g("af2_sps2") * dt**2 + f_rel * e * sqrt_a * sin_e
    return np.stack([x, y, z], axis=-1), clock


def _glonass_deriv(state: NDArray, acc: NDArray) -> NDArray:
    c = GLONASS_CONSTANTS
    mu, ae, j2, w = c["mu_m3ps2"], c["ae_m"], c["j2"], c["omega_radps"]
    r_vec = state[:, :3]
    v = state[:, 3:]
    r2 = np.sum(r_vec**2, axis=1)
    r = np.sqrt(r2)
    a = mu / (r2 * r)
    b = 1.5 * j2 * mu * ae**2 / (r2 * r2 * r)
    z2 = 5.0 * r_vec[:, 2] ** 2 / r2
    x, y, z = r_vec[:, 0], r_vec[:, 1], r_vec[:, 2]
    vx, vy = v[:, 0], v[:, 1]
    ax = -a * x - b * x * (1.0 - z2) + w**2 * x + 2.0 * w * vy + acc[:, 0]
    ay = -a * y - b * y * (1.0 - z2) + w**2 * y - 2.0 * w * vx + acc[:, 1]
    az = -a * z - b * z * (3.0 - z2) + acc[:, 2]
    return np.concatenate([v, np.stack([ax, ay, az], axis=1)], axis=1)


def glonass_state(
    rec: NavRecords, idx: ArrayLike, gps_s: ArrayLike, step_s: float = 60.0
) -> tuple[NDArray, NDArray]:
    """Positions and clock offsets from GLONASS broadcast records (RK4 integration).

    Parameters
    ----------
    rec : NavRecords
        GLONASS records (``rec.kind == "glonass"``).
    idx : array_like of int, shape (m,)
    gps_s : array_like, shape (m,)
    step_s : float
        Largest integration step (every pair uses the same number of equal steps, at most this
        long; 60 s keeps the integration error below a millimetre over 15 min).

    Returns
    -------
    pos_ecef_m : ndarray, shape (m, 3)
        PZ-90 position (equal to ITRF within centimetres since PZ-90.11, 2014).
    clock_s : ndarray, shape (m,)
        -TauN + GammaN (t - tb).
    """
    if rec.kind != "glonass":
        raise ValueError(f"glonass_state needs GLONASS records, got kind={rec.kind!r}")
    if step_s <= 0:
        raise ValueError(f"step_s must be positive, got {step_s}")
    idx = np.asarray(idx, np.intp)
    t = np.asarray(gps_s, float)
    vals = rec.values[idx]
    f = rec.fields
    km = 1000.0
    state = np.stack(
        [
            vals[:, f.index(k)] * km
            for k in ("x_km", "y_km", "z_km", "vx_kmps", "vy_kmps", "vz_kmps")
        ],
        axis=1,
    )
    acc = np.stack([vals[:, f.index(k)] * km for k in ("ax_kmps2", "ay_kmps2", "az_kmps2")], axis=1)
    dt = t - rec.ref_gps_s[idx]
    n_steps = int(np.ceil(np.max(np.abs(dt)) / step_s)) if len(dt) else 0
    if n_steps:
        h = (dt / n_steps)[:, None]
        for _ in range(n_steps):
            k1 = _glonass_deriv(state, acc)
            k2 = _glonass_deriv(state + 0.5 * h * k1, acc)
            k3 = _glonass_deriv(state + 0.5 * h * k2, acc)
            k4 = _glonass_deriv(state + h * k3, acc)
            state = state + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    clock = vals[:, f.index("minus_tau_n_s")] + vals[:, f.index("gamma_n")] * dt
    return state[:, :3], clock
