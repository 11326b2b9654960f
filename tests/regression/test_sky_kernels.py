"""Regression: the sky segmentation's optimised kernels against the implementations they
replaced (kept here verbatim) and against OpenCV.

These pin an optimisation, not correctness: they fail when a faster kernel stops giving the
earlier result (bit for bit where stated). Correctness is tested against independent ground
truth in tests/predisat/sky.
"""


from __future__ import annotations

import numpy as np
import pytest

from predisat.sky.segment import (
    SkyOptions,
    segment_sky,
    skyline_from_mask,
)

H, W = 240, 320




class _MapClassifier:
    """A stand-in probability model: returns a fixed working-resolution sky probability."""

    def __init__(self, prob: np.ndarray) -> None:
        self.prob = prob.astype(np.float32)
        self.max_side_px = max(prob.shape)

    def predict_image(self, image_bgr: np.ndarray) -> np.ndarray:
        return self.prob


def _blobs(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A probability map of random blobs (smoothed noise), many regions and holes."""
    import cv2

    noise = rng.random((h, w)).astype(np.float32)
    sigma = float(rng.uniform(0.7, 3.0))
    p = cv2.GaussianBlur(noise, (0, 0), sigma)
    p = (p - p.min()) / max(float(p.max() - p.min()), 1e-6)
    return np.asarray(p + np.linspace(0.25, -0.25, h, dtype=np.float32)[:, None], np.float32)


@pytest.mark.parametrize("connectivity", [4, 8])
def test_run_components_match_opencv_regions_areas_and_boxes(connectivity: int) -> None:
    import cv2

    from predisat.sky.morphology import RunComponents

    rng = np.random.default_rng(connectivity)
    for k in range(300):
        h, w = (int(v) for v in rng.integers(1, 40, 2))
        m = rng.random((h, w)) < rng.random() if k % 2 else _blobs(rng, h, w) > 0.5
        cc = RunComponents.of(m, connectivity)
        n, lbl, st, _ = cv2.connectedComponentsWithStats(m.view(np.uint8),
                                                         connectivity=connectivity)  # fmt: skip
        assert cc.n == n - 1
        # OpenCV may number the regions otherwise: match them by each run's pixels
        first = np.array([lbl[cc.row[np.argmax(cc.label == q)], cc.start[np.argmax(cc.label == q)]]
                          for q in range(cc.n)], int)  # fmt: skip
        assert np.unique(first).size == cc.n and (first > 0).all()
        painted = np.zeros((h, w), int)
        for r, a, b, q in zip(cc.row, cc.start, cc.stop, cc.label, strict=True):
            assert m[r, a:b].all() and (a == 0 or not m[r, a - 1]) and (b == w or not m[r, b])
            painted[r, a:b] = first[q]
        np.testing.assert_array_equal(painted, lbl)
        s = st[first]
        np.testing.assert_array_equal(cc.area, s[:, cv2.CC_STAT_AREA])
        np.testing.assert_array_equal(cc.left, s[:, cv2.CC_STAT_LEFT])
        np.testing.assert_array_equal(cc.top, s[:, cv2.CC_STAT_TOP])
        np.testing.assert_array_equal(cc.right, s[:, cv2.CC_STAT_LEFT] + s[:, cv2.CC_STAT_WIDTH])
        np.testing.assert_array_equal(cc.bottom, s[:, cv2.CC_STAT_TOP] + s[:, cv2.CC_STAT_HEIGHT])
        # painting and summing selected regions: what the label image gives
        sel = rng.random(cc.n) < 0.5
        got = m.copy()
        cc.paint(got, sel, False)
        keep = np.ones(n, bool)
        keep[first[sel]] = False
        np.testing.assert_array_equal(got, m & keep[lbl])
        # float64 values with full mantissas: a sum in another order would differ
        values = rng.random((h, w)).astype(np.float32 if k % 3 == 0 else np.float64)
        sums = cc.sums(values, sel)
        ref = np.bincount(lbl.ravel(), values.ravel(), n)[first]
        assert np.array_equal(sums[sel], ref[sel]) and not sums[~sel].any()  # bit for bit
        # largest value and "touches a mask" per region, against the label image
        maxes = cc.maxes(values, sel)
        ref_max = np.full(n, -np.inf)
        np.maximum.at(ref_max, lbl.ravel(), values.ravel().astype(np.float64))
        assert np.array_equal(maxes[sel], ref_max[first][sel]) and np.isneginf(maxes[~sel]).all()
        probe = rng.random((h, w)) < 0.05
        touched = np.zeros(n, bool)
        touched[np.unique(lbl[probe & m])] = True
        np.testing.assert_array_equal(cc.touching(probe), touched[first])
        lowest = cc.row == cc.bottom[cc.label] - 1  # runs in each region's lowest row
        low = np.zeros(n, bool)
        for q in range(cc.n):
            r = int(cc.bottom[q]) - 1
            low[first[q]] = bool((probe[r] & (lbl[r] == first[q])).any())
        np.testing.assert_array_equal(cc.touching(probe, lowest), low[first])


def _reference_learned_rules(
    prob: np.ndarray, valid: np.ndarray, opt: SkyOptions
) -> np.ndarray:
    """The region rules of the learned methods as written with OpenCV's component statistics
    (the code before 2026-12-03), before the sky gaps and the thin-structure policy."""
    import cv2

    h, w = prob.shape
    sky = prob >= 0.5
    sky &= valid
    n_valid = max(int(valid.sum()), 1)
    if sky.any() and not opt.fisheye:
        n, lbl, stats, _ = cv2.connectedComponentsWithStats(sky.astype(np.uint8), connectivity=8)
        area = stats[:, cv2.CC_STAT_AREA]
        keep = ((stats[:, cv2.CC_STAT_TOP] == 0) & (area >= opt.min_sky_fraction * n_valid)) | (
            area >= opt.min_island_fraction * n_valid
        )
        keep[0] = False
        if not keep[1:].all():
            sky = keep[lbl]
    if opt.max_hole_fraction > 0 and (~sky & valid).any():
        n, lbl, stats, _ = cv2.connectedComponentsWithStats(
            (~sky & valid).astype(np.uint8), connectivity=4
        )
        x0, y0 = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
        x1, y1 = x0 + stats[:, cv2.CC_STAT_WIDTH], y0 + stats[:, cv2.CC_STAT_HEIGHT]
        inner = (x0 > 0) & (y0 > 0) & (x1 < w) & (y1 < h)
        if opt.fisheye:
            inner[:] = True
        area = stats[:, cv2.CC_STAT_AREA]
        small_hole = inner & (area < opt.max_hole_fraction * n_valid)
        uncertain = inner & (area < opt.uncertain_hole_fraction * n_valid)
        uncertain[0] = False
        if uncertain.any():
            mean_p = np.bincount(lbl.ravel(), prob.ravel(), n) / np.maximum(area, 1)
            small_hole |= uncertain & (mean_p >= opt.uncertain_hole_probability)
        small_hole[0] = False
        if small_hole.any():
            sky |= small_hole[lbl]
    return sky


@pytest.mark.parametrize("fisheye", [False, True])
def test_learned_region_rules_match_the_opencv_reference(
    fisheye: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    import predisat.sky.perceptron

    rng = np.random.default_rng(7 + fisheye)
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(24, 90, 2))
        p = _blobs(rng, h, w)
        # the full-resolution probability is given: the rules alone are compared
        monkeypatch.setattr(predisat.sky.perceptron, "sky_probability", lambda *a, _p=p, **k:
        _p.copy())
        # loose fractions so that every rule fires somewhere
        opt = SkyOptions(  # the frame is flat grey: the grey-pixel rule (not compared) off
            fisheye=fisheye, thin_px=0, detect_gaps=False, grey_sky_probability=0.5,
            min_island_fraction=float(rng.uniform(0.0, 0.05)),
            min_sky_fraction=float(rng.uniform(0.0, 0.01)),
            max_hole_fraction=float(rng.uniform(0.0, 0.01)),
            uncertain_hole_fraction=float(rng.uniform(0.0, 0.1)),
            uncertain_hole_probability=float(rng.uniform(0.2, 0.45)),
        )  # fmt: skip
        seg = segment_sky(np.full((h, w, 3), 128, np.uint8), opt, _MapClassifier(p))
        valid = seg.valid_mask
        prob = np.where(valid, p, 0.0).astype(np.float32) if fisheye else p
        np.testing.assert_array_equal(seg.sky_mask, _reference_learned_rules(prob, valid, opt))


def _reference_skyline(sky: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    valid = np.ones_like(sky) if valid is None else valid
    obstacle = valid & ~sky
    first = np.where(obstacle.any(axis=0), obstacle.argmax(axis=0), sky.shape[0]).astype(float)
    first -= 0.5
    first[~valid.any(axis=0)] = np.nan
    return first


def test_skyline_from_mask_matches_a_whole_frame_argmax() -> None:
    rng = np.random.default_rng(11)
    for k in range(200):
        h, w = (int(v) for v in rng.integers(1, 30, 2))
        sky = rng.random((h, w)) < rng.uniform(0.5, 1.0)
        valid = None if k % 3 == 0 else rng.random((h, w)) < rng.uniform(0.0, 1.0)
        got = skyline_from_mask(sky, valid)
        ref = _reference_skyline(sky, valid)
        assert got.dtype == ref.dtype and np.array_equal(got, ref, equal_nan=True)


def _reference_probability_confidence(
    prob: np.ndarray, skyline_row: np.ndarray, valid: np.ndarray | None, band: int, gap: int
) -> np.ndarray:
    """:func:`probability_confidence` as written with numpy gathers (before 2026-12-03)."""
    p, s = np.asarray(prob), np.asarray(skyline_row, float)
    h, w = p.shape
    valid = np.ones((h, w), bool) if valid is None else valid
    cols = np.arange(w)
    steps = np.arange(band)[:, None]

    def mean(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rows = a[None, :] + steps
        rc = np.clip(rows, 0, h - 1)
        ok = (rows >= 0) & (rows < b[None, :]) & (rows < h) & valid[rc, cols]
        total = np.where(ok, 2.0 * p[rc, cols].astype(float) - 1.0, 0.0).sum(axis=0)
        n = ok.sum(axis=0)
        return total / np.maximum(n, 1), n

    b0 = np.where(np.isfinite(s), s + 0.5, 0).astype(int)
    up, n_up = mean(b0 - gap - band, b0 - gap)
    dn, n_dn = mean(b0 + gap, b0 + gap + band)
    conf = np.zeros(w)
    both = (n_up > 0) & (n_dn > 0)
    conf[both] = np.minimum(up, -dn)[both]
    only_up, only_dn = (n_up > 0) & (n_dn == 0), (n_up == 0) & (n_dn > 0)
    conf[only_up], conf[only_dn] = up[only_up], -dn[only_dn]
    conf[~np.isfinite(s)] = 0.0
    return np.clip(conf, 0.0, 1.0)


def test_probability_confidence_matches_the_numpy_gathers_bit_for_bit() -> None:
    from predisat.sky.segment import probability_confidence

    rng = np.random.default_rng(5)
    for k in range(200):
        h, w = (int(v) for v in rng.integers(2, 80, 2))
        dtype = np.float32 if k % 2 else np.float64
        prob = rng.random((h, w)).astype(dtype)
        s = rng.integers(-3, h + 3, w) - 0.5
        s[rng.random(w) < 0.1] = np.nan
        valid = None if k % 3 == 0 else rng.random((h, w)) < 0.8
        band, gap = int(rng.integers(1, 40)), int(rng.integers(0, 5))
        got = probability_confidence(prob, s, valid, band, gap)
        ref = _reference_probability_confidence(prob, s, valid, band, gap)
        assert np.array_equal(got, ref), k


def _reference_guided(guide: np.ndarray, src: np.ndarray, radius_px: int, eps: float,
                      s: int) -> np.ndarray:  # fmt: skip
    """The guided filter as written before 2026-12-03 (``ma * i + mb`` into a new array)."""
    import cv2

    i, p = np.asarray(guide, np.float32), np.asarray(src, np.float32)
    h, w = i.shape
    if s > 1:
        size = (max(1, round(w / s)), max(1, round(h / s)))
        i_low = cv2.resize(i, size, interpolation=cv2.INTER_AREA)
        p_low = cv2.resize(p, size, interpolation=cv2.INTER_AREA if p.shape[1] > size[0]
                           else cv2.INTER_LINEAR)  # fmt: skip
        r = max(1, round(radius_px / s))
    else:
        i_low, p_low, r = i, p, int(radius_px)
    k = (2 * r + 1,) * 2

    def box(a: np.ndarray) -> np.ndarray:
        return np.asarray(cv2.boxFilter(a, cv2.CV_32F, k, borderType=cv2.BORDER_REFLECT))

    mi, mp = box(i_low), box(p_low)
    a = (box(i_low * p_low) - mi * mp) / (box(i_low * i_low) - mi * mi + eps)
    b = mp - a * mi
    ma, mb = box(a), box(b)
    if s > 1:
        ma = cv2.resize(ma, (w, h), interpolation=cv2.INTER_LINEAR)
        mb = cv2.resize(mb, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.asarray(ma * i + mb, np.float32)


def test_sky_probability_is_the_reference_arithmetic_and_leaves_the_model_map_alone() -> None:
    """In-place products and clipping since 2026-12-03: the same probabilities, bit for bit,
    and the classifier's own map is not written to."""
    import cv2

    from predisat.sky.features import working_size
    from predisat.sky.perceptron import sky_probability

    rng = np.random.default_rng(8)
    for k in range(24):
        side = int(rng.choice([40, 90, 200, 330]))  # working size 40: scale 1, < 2 and >= 2
        h, w = side, int(side * rng.uniform(1.0, 1.5))
        img = cv2.GaussianBlur(rng.integers(0, 256, (h, w, 3), dtype=np.uint8), (0, 0), 2.0)
        ww, hh = working_size((h, w), 40)
        p = _blobs(rng, hh, ww)
        clf = _MapClassifier(p)
        clf.max_side_px = 40
        before = clf.prob.copy()
        refine = k % 4 != 0
        got = sky_probability(img, clf, refine=refine)
        assert np.array_equal(clf.prob, before)
        scale = max(h, w) / 40
        if refine and scale > 1.0:
            sub = 2 if scale >= 2.0 else 1
            grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32) / 255.0
            src = clf.prob if sub > 1 else cv2.resize(clf.prob, (w, h))
            ref = _reference_guided(grey, src, max(2, round(1.5 * scale)), 1e-3, sub)
        else:
            ref = cv2.resize(clf.prob, (w, h), interpolation=cv2.INTER_LINEAR)
        assert np.array_equal(got, np.clip(ref, 0.0, 1.0)), k
