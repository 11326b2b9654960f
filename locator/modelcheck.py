"""Whether a pseudorange error model applies to a run's data, told to the user.

``locator run`` and ``locator balises`` decide the same way
(:meth:`predisat.gnss.errormodel.ErrorModelFile.mismatches` against the data's
:class:`~predisat.gnss.errormodel.ReceiverProfile`, and
:meth:`~predisat.gnss.errormodel.ErrorModelFile.depth_shortfall` against the widest pair
interval claimed): a model that does not apply, or not as deep, gives positions without a
safety claim (every epoch flagged ``NO_ERROR_MODEL``) unless forced (``FORCED_ERROR_MODEL``,
not a safety claim) or the Gaussian tail is assumed (``GAUSSIAN_TAIL``); docs/errormodel.md.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import argparse

    from locator.fde import LocatorConfig
    from locator.sim.simfile import SimRun
    from predisat.gnss.errormodel import ErrorModelFile, ReceiverProfile

__all__ = ["calibrated_on", "deepest_k", "model_use", "sim_profile"]


def sim_profile(sim: SimRun, constellation: str) -> ReceiverProfile:
    """The receiver profile of a simulated run: the simulated receiver with the systems of
    ``constellation`` that the run carries."""
    import numpy as np

    from locator.errorfit import simulated_profile
    from predisat.availability.satellites import select_satellites

    # the systems the run received, not every one it carries: a pooled calibration covers
    # only the systems that gave residuals (QZSS never in view in Belgium), and a system the
    # run never received needs no model (a review: `run --constellation all` on the very
    # simulation the model was calibrated on made no claim, "system J was not calibrated")
    used = set(select_satellites(sim.sats, constellation))
    got = np.flatnonzero(np.asarray(sim.received, bool).any(axis=0))
    seen = {sim.sats[j][0] for j in got if sim.sats[j] in used}
    return simulated_profile(sorted(seen or {s[0] for s in used}))


def _calibrate_hint(args: argparse.Namespace) -> str:
    """The ``locator calibrate`` call that makes a model for the data of ``args``: a phone's
    log against its ground truth, else static observations (a user trial: a phone was told to
    give RINEX)."""
    if getattr(args, "device_gnss", None):
        return ("`locator calibrate --device-gnss CSV --truth CSV` (logs of the same phone "
                "model with their ground truth; docs/errormodel.md)")  # fmt: skip
    dual = " --dual-frequency" if getattr(args, "dual_frequency", False) else ""
    return (f"`locator calibrate --obs FILE --nav NAV{dual}` (static observations of the same "
            "receiver, antenna and codes at a known position; docs/errormodel.md)")  # fmt: skip


def model_use(
    mf: ErrorModelFile,
    profile: ReceiverProfile,
    args: argparse.Namespace,
    k_max: float,
    command: str = "locator run",
) -> tuple[str, dict[str, Any]]:
    """How the model may support claims on data of ``profile``, told to the user, and the
    record of it for ``run.json``.

    Parameters
    ----------
    mf : ErrorModelFile
        The model (``--error-model`` or the built-in one).
    profile : ReceiverProfile
        What the data is.
    args : argparse.Namespace
        ``error_model`` (the file or None), ``force_error_model``, and where the command has
        them ``assume_gaussian_tail``, ``obs`` / ``device_gnss`` (the data file).
    k_max : float
        The widest pair interval's ``k`` a claim may rest on (:func:`deepest_k`).
    command : str
        The command named in the messages (printed on stderr).

    Returns
    -------
    use : {"calibrated", "gaussian_tail", "forced", "none"}
    record : dict

    ``"calibrated"``: it applies, tails checked at least as deep as ``k_max`` claims;
    ``"gaussian_tail"``: it applies, the claims rest on its Gaussian tail beyond the checked
    depth (``--assume-gaussian-tail``); ``"forced"``: it does not apply and
    ``--force-error-model`` was given (not a safety claim); ``"none"``: no claim.
    """
    name = args.error_model or "the built-in model (a = b = 2 m, the simulator's noise)"
    why = mf.mismatches(profile)
    short = [] if why else mf.depth_shortfall(profile.systems, k_max)
    assume = getattr(args, "assume_gaussian_tail", False)
    if why:
        use = "forced" if args.force_error_model else "none"
    else:
        use = "gaussian_tail" if short and assume else ("none" if short else "calibrated")
    app = mf.applicability
    cls = app.receiver_class if app is not None else ""
    by_class = bool(cls) and profile.receiver_class == cls
    record: dict[str, Any] = {
        "file": args.error_model or "built-in",
        "use": use,
        "data": profile.describe(),
        # what made it apply: the receiver class (any receiver of it) or the names calibrated
        "applies_by": (f"class {cls}" if by_class else "receiver and antenna"),
        "model_receivers": [] if app is None else list(app.receivers),
        "mismatches": list(why),
        "depth_shortfall": list(short),
        "k_sigma_max": round(k_max, 4),
        "systems": {
            s: {
                "n_independent": m.n_independent,
                "tail_probability": (
                    m.tail_probability if math.isfinite(m.tail_probability) else None
                ),
            }
            for s, m in sorted(mf.systems.items())
            if s in profile.systems
        },
    }
    if use == "none" and why:
        print(
            f"{command}: NO SAFETY CLAIM: {name} does not apply to this data "
            f"({profile.describe()}): {'; '.join(why)}. Positions are given, every epoch flagged "
            f"NO_ERROR_MODEL. Make a model for this receiver with {_calibrate_hint(args)} and "
            "pass it with --error-model (or --force-error-model to claim under a model not "
            "calibrated for this data: not safe)",
            file=sys.stderr,
        )
    elif use == "none":
        print(
            f"{command}: NO SAFETY CLAIM: the integrity risk asks for pair intervals of k up "
            f"to {k_max:.3f}, deeper than {name} was checked: {'; '.join(short)}. Positions "
            "are given, every epoch flagged NO_ERROR_MODEL. Calibrate on more data, claim a "
            "larger risk (--integrity-risk, or --k-sigma within the checked k)"
            + (", or pass --assume-gaussian-tail to claim under the Gaussian shape beyond the "
               "checked depth (recorded in run.json, every epoch flagged GAUSSIAN_TAIL)"
               if hasattr(args, "assume_gaussian_tail") else "")
            + " (docs/errormodel.md)",
            file=sys.stderr,
        )
    elif use == "forced":
        print(f"{command}: warning: --force-error-model: intervals under {name}, which does "
              f"not apply to this data: {'; '.join(why)}. NOT A SAFETY CLAIM: every epoch is "
              "flagged FORCED_ERROR_MODEL and the output records it", file=sys.stderr)  # fmt: skip
    elif use == "gaussian_tail":
        print(f"{command}: warning: --assume-gaussian-tail: {'; '.join(short)}. The claims "
              "rest on the Gaussian shape beyond that depth: every epoch is flagged "
              "GAUSSIAN_TAIL and the output records it", file=sys.stderr)  # fmt: skip
    own = calibrated_on(mf, getattr(args, "obs", None) or getattr(args, "device_gnss", None))
    if own and use != "none":
        print(f"{command}: warning: {name} was calibrated on {own}, the data of this run: "
              "its claims here are no independent check of the model (validate on other days "
              "or receivers: docs/errormodel.md, leave one receiver out)", file=sys.stderr)
        record["calibrated_on_this_data"] = True
    if use in ("calibrated", "gaussian_tail") and by_class and app is not None:
        print(f"{command}: error model applied by receiver class {cls!r} (the data's "
              f"{'declared' if getattr(args, 'receiver_class', None) else 'guessed'} class), "
              f"calibrated on {', '.join(app.receivers)}", file=sys.stderr)  # fmt: skip
    if use in ("calibrated", "gaussian_tail"):
        for sys_ in profile.systems:
            m = mf.systems.get(sys_)
            if m is not None and not math.isnan(m.tail_probability):
                print(f"{command}: error model for {sys_}: {m.n_independent} independent "
                      f"samples, its tails were checked to {m.tail_probability:.2g} per "
                      "pseudorange", file=sys.stderr)  # fmt: skip
    return use, record


def calibrated_on(mf: ErrorModelFile, data: str | None) -> str:
    """The input of the model's calibration that is the run's data file ("" if none)."""
    if data is None or mf.applicability is None:
        return ""
    target = Path(data).resolve()
    for src in mf.applicability.sources:
        try:
            if Path(src).resolve() == target:
                return str(src)
        except OSError:  # a source path the machine cannot resolve is not this file
            continue
    return ""


def deepest_k(locator: LocatorConfig) -> float:
    """The widest pair interval's ``k`` a claim may rest on (the fixed ``k``, or under a budget
    the ``k`` of a single independent pair).

    Not the claiming modes' nominal ``k``: active integrity drops blunt pairs and widens the
    others to the ``k`` of the disjoint pairs left (:meth:`locator.fde.LocatorConfig.
    k_sigma_for`), and a union of 4-5 satellites may keep one, so a claim may rest on
    ``budget.k_sigma(1)`` (7.13 at 1e-12 per epoch).
    """
    if locator.budget is None:
        return float(locator.model.k_sigma)
    return float(locator.budget.k_sigma(1))
