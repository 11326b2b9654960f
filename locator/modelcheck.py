"""Whether a pseudorange error model applies to a run's data, told to the user.

``locator run`` and ``locator balises`` decide the same way
(:meth:`predisat.gnss.errormodel.ErrorModelFile.mismatches` against the data's
:class:`~predisat.gnss.errormodel.ReceiverProfile`): a model that does not apply gives
positions without a safety claim (every epoch flagged ``NO_ERROR_MODEL``) unless forced.
"""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

    from locator.sim.simfile import SimRun
    from predisat.gnss.errormodel import ErrorModelFile, ReceiverProfile

__all__ = ["model_applies", "sim_profile"]


def sim_profile(sim: SimRun, constellation: str) -> ReceiverProfile:
    """The receiver profile of a simulated run: the simulated receiver with the systems of
    ``constellation`` that the run carries."""
    from locator.errorfit import simulated_profile
    from predisat.availability.satellites import select_satellites

    used = select_satellites(sim.sats, constellation)
    return simulated_profile(sorted({s[0] for s in used}))


def model_applies(
    mf: ErrorModelFile,
    profile: ReceiverProfile,
    args: argparse.Namespace,
    command: str = "locator run",
) -> bool:
    """Whether the model may support a safety claim on data of ``profile``; tells why not.

    Parameters
    ----------
    mf : ErrorModelFile
        The model (``--error-model`` or the built-in one).
    profile : ReceiverProfile
        What the data is.
    args : argparse.Namespace
        ``error_model`` (the file or None) and ``force_error_model``.
    command : str
        The command named in the messages (printed on stderr).
    """
    name = args.error_model or "the built-in model (a = b = 2 m, the simulator's noise)"
    why = mf.mismatches(profile)
    if why and not args.force_error_model:
        print(
            f"{command}: NO SAFETY CLAIM: {name} does not apply to this data "
            f"({profile.describe()}): {'; '.join(why)}. Positions are given, every epoch flagged "
            "NO_ERROR_MODEL. Make a model for this receiver with `locator calibrate --obs FILE "
            "--nav NAV` (static observations of the same receiver, antenna and codes at a known "
            "position; docs/errormodel.md) and pass it with --error-model (or --force-error-model "
            "to claim under a model not calibrated for this data: not safe)",
            file=sys.stderr,
        )
        return False
    if why:
        print(f"{command}: warning: --force-error-model: claims under {name}, which does not "
              f"apply to this data: {'; '.join(why)}", file=sys.stderr)  # fmt: skip
    for sys_ in profile.systems:
        m = mf.systems.get(sys_)
        if m is not None and not math.isnan(m.tail_probability):
            checked = (f"its tails were checked to {m.tail_probability:.2g} per pseudorange"
                       if m.tail_probability < 1 else "too few independent samples to check "
                       "any tail")  # fmt: skip
            print(f"{command}: error model for {sys_}: {m.n_independent} independent samples, "
                  f"{checked}", file=sys.stderr)  # fmt: skip
    return True
