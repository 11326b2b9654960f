"""Error-model files (locator-error-model/2): what a model applies to, and the /1 files."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from predisat.gnss.errormodel import (
    MIN_FIT_RESIDUALS,
    Applicability,
    ErrorModel,
    ErrorModelFile,
    ErrorModelFileError,
    IntervalModel,
    ReceiverProfile,
    SystemModel,
    default_model_file,
    read_error_model,
    read_error_model_file,
    write_error_model,
)

GPS = SystemModel(ErrorModel(0.6, 0.4), ("C1C",), 30000, 1500, 0.02)
GAL = SystemModel(ErrorModel(0.9, 0.3), ("C1C", "C1X"), 20000, 900, 0.04)
APP = Applicability(("TRIMBLE NETR9",), ("ASH701073.1     SNOW",), "", "single", 5.0, 88.0,
                    "overbound", ("nya1.crx",))  # fmt: skip


def _profile(rx="TRIMBLE NETR9", ant="ASH701073.1     SNOW", codes=None, **kw):
    return ReceiverProfile(rx, ant, codes or {"G": ("C1C",)}, **kw)


@pytest.fixture
def model_file(tmp_path):
    env = IntervalModel(ErrorModel(0.9, 0.4), 3.0)
    p = write_error_model(tmp_path / "m.json", env, {"note": "x"},
                          systems={"G": GPS, "E": GAL}, applicability=APP)  # fmt: skip
    return read_error_model_file(p)


def test_round_trip_keeps_systems_and_applicability(model_file):
    assert model_file.format == "locator-error-model/2"
    assert model_file.systems == {"G": GPS, "E": GAL} and model_file.applicability == APP
    assert model_file.model == IntervalModel(ErrorModel(0.9, 0.4), 3.0)
    assert read_error_model(model_file.path) == model_file.model
    assert model_file.el_min_deg == 5.0
    # k of a two-sided Gaussian at the checked tail probability: Q^-1(0.01) = 2.326
    assert GPS.k_checked == pytest.approx(2.3263, abs=1e-3)


def test_model_applies_only_to_its_receiver_antenna_codes_and_processing(model_file):
    assert model_file.mismatches(_profile()) == []
    assert model_file.mismatches(_profile(codes={"G": ("C1C",), "E": ("C1X",)})) == []
    # case and blanks do not matter; the receiver's name does
    assert model_file.mismatches(_profile(rx=" trimble  netr9")) == []
    why = model_file.mismatches(_profile(rx="SEPT POLARX5"))
    assert len(why) == 1 and "SEPT POLARX5" in why[0]
    assert "antenna" in " ".join(model_file.mismatches(_profile(ant="LEIAR25.R3      LEIT")))
    assert "system C" in " ".join(model_file.mismatches(_profile(codes={"C": ("C2I",)})))
    assert "C1W" in " ".join(model_file.mismatches(_profile(codes={"G": ("C1W",)})))
    assert "dual" in " ".join(model_file.mismatches(_profile(frequency="dual")))


def test_class_models_and_unknown_receivers(tmp_path):
    phones = Applicability(("Unknown",), ("Unknown",), "phone", el_min_deg=10.0)
    p = write_error_model(tmp_path / "phone.json", IntervalModel(ErrorModel(5.0, 5.0)),
                          systems={"G": GPS}, applicability=phones)  # fmt: skip
    mf = read_error_model_file(p)
    # a receiver named "Unknown" is not identified by the name: only the class can match it
    assert mf.mismatches(_profile("Unknown", "Unknown")) != []
    assert mf.mismatches(_profile("Unknown", "Unknown", receiver_class="phone")) == []
    assert mf.mismatches(_profile(receiver_class="geodetic")) != []


def test_envelope_of_the_systems_used(model_file):
    assert model_file.for_systems(["G"]) == IntervalModel(ErrorModel(0.6, 0.4), 3.0)
    assert model_file.for_systems(["G", "E"]) == IntervalModel(ErrorModel(0.9, 0.4), 3.0)
    # a system without a model: the file's envelope (the run is then not claimed anyway)
    assert model_file.for_systems(["C"]) == model_file.model


def test_v1_files_apply_to_nothing(tmp_path):
    p = tmp_path / "v1.json"
    p.write_text(json.dumps({"format": "locator-error-model/1", "a_m": 1.0, "b_m": 2.0,
                             "min_el_deg": 3.0, "k_sigma": 2.5}))  # fmt: skip
    mf = read_error_model_file(p)
    assert mf.applicability is None and mf.systems == {}
    assert mf.model == IntervalModel(ErrorModel(1.0, 2.0, 3.0), 2.5)
    (why,) = mf.mismatches(_profile())
    assert "locator-error-model/1" in why and str(p) in why


def test_default_model_applies_to_simulations_only():
    d = default_model_file()
    sim = ReceiverProfile("simulated", "simulated", {"G": ("sim",), "E": ("sim",)},
                          receiver_class="simulated")  # fmt: skip
    assert d.mismatches(sim) == []
    assert d.mismatches(_profile()) != []
    assert d.mismatches(_profile("Unknown", "Unknown", receiver_class="phone")) != []


@pytest.mark.parametrize(
    ("edit", "what"),
    [
        (lambda s: s.update(tail_probability=5.0), "tail_probability must be a probability"),
        (lambda s: s.update(n_independent=-5), "n_independent must lie in"),
        (lambda s: s.update(codes="C1C"), "codes must be a list"),
    ],
)
def test_hand_edited_model_values_are_refused_naming_the_field(tmp_path, model_file, edit, what):
    """A user trial's edited files were taken as they were (a tail of 5.0 was then blamed on
    "0 independent samples"; codes "sim" read as three codes)."""
    doc = json.loads(Path(model_file.path).read_text())
    edit(doc["systems"]["G"])
    p = tmp_path / "edited.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ErrorModelFileError, match=rf"edited\.json: bad .*{what}"):
        read_error_model_file(p)


def test_a_newer_model_format_is_named_as_such(tmp_path):
    p = tmp_path / "v3.json"
    p.write_text(json.dumps({"format": "locator-error-model/3", "a_m": 1.0, "b_m": 2.0}))
    with pytest.raises(ErrorModelFileError, match=r"another version \(locator-error-model/3\)"):
        read_error_model_file(p)


def test_bad_v2_file_is_named(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps({"format": "locator-error-model/2", "a_m": 1.0, "b_m": 2.0}))
    with pytest.raises(ErrorModelFileError, match=r"bad\.json.*applicability"):
        read_error_model_file(p)
    with pytest.raises(ValueError, match="receiver_class"):
        ReceiverProfile("x", "y", {}, receiver_class="tractor")


def test_unchecked_tails_and_estimates_support_no_claim(tmp_path):
    thin = SystemModel(ErrorModel(0.6, 0.4), ("C1C",), 240, 12, 1.0)  # no tail point checked
    p = write_error_model(tmp_path / "thin.json", IntervalModel(ErrorModel(0.6, 0.4)),
                          systems={"G": thin}, applicability=APP)  # fmt: skip
    (why,) = read_error_model_file(p).mismatches(_profile())
    assert "12 independent samples" in why
    est = Applicability(APP.receivers, APP.antennas, method="estimate")
    p = write_error_model(tmp_path / "est.json", IntervalModel(ErrorModel(0.6, 0.4)),
                          systems={"G": GPS}, applicability=est)  # fmt: skip
    (why,) = read_error_model_file(p).mismatches(_profile())
    assert "estimate" in why


def test_a_model_whose_tails_were_never_checked_supports_no_claim(tmp_path):
    # null in the file (an overbound made without the sample-size check, or an older file):
    # NaN slips through every ``>=`` test, so it must be refused by name
    nan = SystemModel(ErrorModel(0.6, 0.4), ("C1C",), 30000, 1500, float("nan"))
    p = write_error_model(tmp_path / "nan.json", IntervalModel(ErrorModel(0.6, 0.4)),
                          systems={"G": nan}, applicability=APP)  # fmt: skip
    assert json.loads(p.read_text())["systems"]["G"]["tail_probability"] is None
    (why,) = read_error_model_file(p).mismatches(_profile())
    assert "no tail check" in why
    # a method the reader does not know is no overbound either
    odd = Applicability(APP.receivers, APP.antennas, method="")
    p = write_error_model(tmp_path / "odd.json", IntervalModel(ErrorModel(0.6, 0.4)),
                          systems={"G": GPS}, applicability=odd)  # fmt: skip
    (why,) = read_error_model_file(p).mismatches(_profile())
    assert "is not an overbound" in why
    # the simulator's own model keeps applying to simulated receivers
    sim = ReceiverProfile("simulated", "simulated", {"G": ("sim",)}, receiver_class="simulated")
    assert default_model_file().mismatches(sim) == []
    # ... but a file naming the simulator's method for a real receiver skips no check
    named = Applicability(APP.receivers, APP.antennas, method="simulator noise model")
    p = write_error_model(tmp_path / "named.json", IntervalModel(ErrorModel(0.6, 0.4)),
                          systems={"G": nan}, applicability=named)  # fmt: skip
    why = read_error_model_file(p).mismatches(_profile())
    assert any("no tail check" in w for w in why) and any("not an overbound" in w for w in why)


def test_depth_shortfall_compares_the_claims_k_with_the_checked_tail():
    from scipy.stats import norm

    e = ErrorModel(1.0, 1.0)
    systems = {"G": SystemModel(e, ("C1C",), 5000, 3000, 0.019),
               "E": SystemModel(e, ("C1C",), 5000, 900, 1e-5),
               "S": SystemModel(e, ("sim",), 0, 0, float("nan"))}  # fmt: skip
    mf = ErrorModelFile(IntervalModel(e), systems, Applicability(("R",), ("A",)))
    k_g = norm.isf(0.019 / 2)  # 2.35: the two-sided k of G's checked tail
    k_e = norm.isf(1e-5 / 2)  # 4.42
    assert mf.depth_shortfall(["G", "E"], k_g - 0.01) == []
    (only_g,) = mf.depth_shortfall(["G", "E"], 0.5 * (k_g + k_e))
    assert only_g.startswith("system G was checked to 0.019") and "3000 independent" in only_g
    assert len(mf.depth_shortfall(["G", "E"], k_e + 0.01)) == 2
    # the simulator's own noise model has no checked depth to fall short of
    assert mf.depth_shortfall(["S"], 7.0) == [] and mf.depth_shortfall(["J"], 7.0) == []
    with pytest.raises(ValueError, match="k_sigma"):
        mf.depth_shortfall(["G"], 0.0)


def test_a_pooled_model_applies_to_the_receiver_antenna_pairs_and_codes_it_holds(tmp_path):
    """A user trial: a model of NetR9 + ASH701073 and PolaRx5 + ASH701945 claimed for PolaRx5 +
    ASH701073 (never calibrated together), and Galileo C1C (19 epochs of the PolaRx5) under
    the NetR9's C1X samples."""
    pairs = (
        ("TRIMBLE NETR9", "ASH701073.1     SNOW", (("E", ("C1X",), 20990), ("G", ("C1C",), 32596))),
        ("SEPT POLARX5", "ASH701945E_M    NONE", (("E", ("C1C",), 138), ("G", ("C1C",), 165))),
    )
    app = Applicability(("SEPT POLARX5", "TRIMBLE NETR9"),
                        ("ASH701073.1     SNOW", "ASH701945E_M    NONE"), "", "single", 5.0, 72.7,
                        "overbound", ("nya1.crx", "kms3.crx"), pairs)  # fmt: skip
    env = IntervalModel(ErrorModel(0.9, 0.4), 2.0)
    p = write_error_model(tmp_path / "m.json", env, systems={"G": GPS, "E": GAL},
                          applicability=app)  # fmt: skip
    mf = read_error_model_file(p)
    assert mf.applicability.pairs == pairs  # round trip
    # a count edited by hand to no whole number is refused, naming the file
    text = json.loads(p.read_text())
    text["applicability"]["pairs"][0]["systems"]["E"]["n_residuals"] = 1.5
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(text))
    with pytest.raises(ErrorModelFileError, match=r"bad\.json.*n_residuals"):
        read_error_model_file(bad)
    assert mf.mismatches(_profile()) == []
    # the PolaRx5's own 165 GPS residuals could not have been fitted alone: the pooled
    # figures are the NetR9's, so the model does not cover it by name
    why = mf.mismatches(_profile("SEPT POLARX5", "ASH701945E_M    NONE"))
    assert len(why) == 1 and "only 165 residuals" in why[0], why
    rich = tuple((r, a, tuple((s_, c, n + MIN_FIT_RESIDUALS) for s_, c, n in per))
                 for r, a, per in pairs)  # fmt: skip
    mf_rich = ErrorModelFile(env, {"G": GPS, "E": GAL}, dataclasses.replace(app, pairs=rich))
    assert mf_rich.mismatches(_profile("SEPT POLARX5", "ASH701945E_M    NONE")) == []
    why = mf.mismatches(_profile("SEPT POLARX5", "ASH701073.1     SNOW"))
    assert len(why) == 1 and "never calibrated together" in why[0]
    # Galileo C1C: in the model's codes (the PolaRx5's), not the NetR9's
    why = mf.mismatches(_profile(codes={"E": ("C1C",)}))
    assert len(why) == 1 and "other receivers or antennas only" in why[0], why
    # a class model is for any receiver of the class: the pairs do not restrict it
    cls = ErrorModelFile(env, {"G": GPS}, dataclasses.replace(app, receiver_class="geodetic"))
    assert cls.mismatches(_profile("LEICA GR50", "LEIAR25.R4      LEIT",
                                   receiver_class="geodetic")) == []  # fmt: skip
    # an older file pooling receivers without its pairs: applies by name to none of them
    old = ErrorModelFile(env, {"G": GPS}, dataclasses.replace(app, pairs=()))
    why = old.mismatches(_profile())
    assert len(why) == 1 and "without recording which were calibrated together" in why[0]
    # ... one receiver and one antenna need no pairs
    assert ErrorModelFile(env, {"G": GPS}, APP).mismatches(_profile()) == []


def test_a_dual_frequency_run_under_its_stations_single_frequency_model_is_told_why():
    """A user trial (n8): NYA1's dual-frequency run under NYA1's own single-frequency model was
    told its codes "were calibrated on other receivers or antennas only" (the model holds one
    receiver), and the message listed the data's codes as "G C1C+C2W+C1C+C2X" (pairs and the
    list both joined by "+")."""
    pairs = (("TRIMBLE NETR9", "ASH701073.1     SNOW", (("G", ("C1C",), 32594),)),)
    app = dataclasses.replace(APP, pairs=pairs)
    mf = ErrorModelFile(IntervalModel(ErrorModel(0.9, 0.4), 2.0), {"G": GPS}, app)
    dual = _profile(codes={"G": ("C1C+C2W", "C1C+C2X")}, frequency="dual")
    why = " ; ".join(mf.mismatches(dual))
    assert "other receivers" not in why, why
    assert "not calibrated" in why and "single-frequency model" in why
    assert "C1C+C2W or C1C+C2X" in dual.describe() and "C2W+C1C" not in dual.describe()
