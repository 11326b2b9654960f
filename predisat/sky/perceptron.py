"""The learned per-pixel sky classifier: a small neural network on :mod:`predisat.sky.features`.

OpenCV 5 no longer ships the ``ml`` module, so the model is a plain multilayer perceptron
(standardised features -> ReLU hidden layers -> sigmoid sky probability) evaluated and trained
with numpy: a few thousand weights, about a millisecond per 160x120 working image, no extra
dependency. The shipped model ``predisat/data/models/sky_mlp.json`` (weights and card: training
data, seeds, features, held-out accuracy in one JSON file) is trained by
``scripts/train_sky.py`` on synthetic frames only, reproducibly, and is loaded without network.

>>> clf = SkyClassifier.default()
>>> prob = clf.predict_image(cv2.imread("frame.jpg"))    # (h, w) at working resolution
"""

from __future__ import annotations

import itertools
import json
import os
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky.features import FEATURE_NAMES, image_features, working_image

if TYPE_CHECKING:  # an alias only: the segmentation loads no module outside predisat.sky
    from predisat.jsontypes import JsonDict

__all__ = [
    "DEFAULT_MODEL",
    "SkyClassifier",
    "SkyModel",
    "guided_filter",
    "label_to_sky",
    "sample_pixels",
    "sigmoid",
    "sky_probability",
    "train_sky_model",
]

DEFAULT_MODEL = "sky_mlp.json"
_FORMAT = "predisat-sky-mlp"


def label_to_sky(label: ArrayLike) -> NDArray[np.bool_]:
    """Sky of a synthetic label image (255 sky, 128 thin L-band-transparent = sky, 0 obstacle)."""
    return np.asarray(np.asarray(label) >= 128)


def sigmoid(z: NDArray) -> NDArray:
    """The logistic function ``1 / (1 + exp(-z))`` elementwise, same shape as ``z``.

    Computed as ``0.5 (1 + tanh(z / 2))``, which cannot overflow (shared with
    :mod:`predisat.sky.network`).
    """
    return np.asarray(0.5 * (1.0 + np.tanh(0.5 * z)))  # overflow-free logistic


class SkyModel(Protocol):
    """A sky probability model: :class:`SkyClassifier`, :class:`predisat.sky.network.SkyNet` or
    :class:`predisat.sky.network.SkyEnsemble` (what :func:`sky_probability` and
    :func:`predisat.sky.segment.segment_sky` run)."""

    @property
    def max_side_px(self) -> int:
        """Longest side of the working image, pixels."""
        ...

    def predict_image(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        """Sky probability, shape (h, w) at working resolution, of an upright BGR image."""
        ...


@dataclass(frozen=True)
class SkyClassifier:
    """A trained sky classifier (multilayer perceptron) and its metadata.

    Attributes
    ----------
    weights : tuple of ndarray
        Layer matrices, shapes ``(n_features, n1), (n1, n2), ..., (n_k, 1)``.
    biases : tuple of ndarray
        Layer biases, shapes ``(n1,), ..., (1,)``.
    mean, scale : ndarray, shape (n_features,)
        Feature standardisation ``(x - mean) / scale``.
    max_side_px : int
        Longest side of the working image the features are computed on.
    feature_names : tuple of str
        Must equal :data:`predisat.sky.features.FEATURE_NAMES` of the running code.
    card : dict
        Training metadata (data, seeds, parameters, held-out accuracy).
    """

    weights: tuple[NDArray[np.float32], ...]
    biases: tuple[NDArray[np.float32], ...]
    mean: NDArray[np.float32]
    scale: NDArray[np.float32]
    max_side_px: int = 160
    feature_names: tuple[str, ...] = FEATURE_NAMES
    card: JsonDict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if tuple(self.feature_names) != FEATURE_NAMES:
            raise ValueError(
                "the model was trained on features "
                f"{list(self.feature_names)} but this code computes {list(FEATURE_NAMES)}; "
                "retrain it with scripts/train_sky.py"
            )
        n = len(FEATURE_NAMES)
        shapes = [w.shape for w in self.weights]
        ok = (
            len(self.weights) == len(self.biases) >= 1
            and shapes[0][0] == n
            and shapes[-1][1] == 1
            and all(a[1] == b[0] for a, b in itertools.pairwise(shapes))
            and all(b.shape == (w.shape[1],) for w, b in zip(self.weights, self.biases,
                                                               strict=True))
            and self.mean.shape == self.scale.shape == (n,)
        )
        if not ok:
            raise ValueError(f"inconsistent layer shapes {shapes} for {n} features")

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> SkyClassifier:
        """Read a model written by :meth:`save` (one JSON file: weights and card)."""
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(
                f"sky model {p} does not exist; train it with scripts/train_sky.py"
            )
        data = json.loads(p.read_text(encoding="utf-8"))
        if data.get("format") != _FORMAT:
            raise ValueError(f"{p} is not a PREDISAT sky model (format {data.get('format')!r})")

        def arr(v: ArrayLike) -> NDArray[np.float32]:
            return np.asarray(v, np.float32)

        return cls(
            tuple(arr(w) for w in data["weights"]),
            tuple(arr(b) for b in data["biases"]),
            arr(data["mean"]),
            arr(data["scale"]),
            int(data["max_side_px"]),
            tuple(data["features"]),
            dict(data.get("card", {})),
        )

    @classmethod
    def default(cls) -> SkyClassifier:
        """The model shipped in ``predisat/data/models`` (read once, then shared read-only)."""
        return _default_classifier()

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the model (weights, standardisation, features, card) as one JSON file."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)

        def lst(a: NDArray) -> list[object]:
            return np.round(np.asarray(a, np.float64), 7).tolist()

        data = {
            "format": _FORMAT,
            "version": 1,
            "max_side_px": self.max_side_px,
            "features": list(FEATURE_NAMES),
            "card": self.card,
            "mean": lst(self.mean),
            "scale": lst(self.scale),
            "weights": [lst(w) for w in self.weights],
            "biases": [lst(b) for b in self.biases],
        }
        p.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        return p

    def logit(self, features: ArrayLike) -> NDArray[np.float32]:
        """Log-odds of sky of feature rows ``(n, n_features)`` -> ``(n,)``."""
        x = np.asarray(features, np.float32)
        if x.ndim != 2 or x.shape[1] != len(FEATURE_NAMES):
            raise ValueError(f"features must have shape (n, {len(FEATURE_NAMES)}), got {x.shape}")
        ws, bs = self._folded
        a = x
        for w, b in zip(ws[:-1], bs[:-1], strict=True):
            a = a @ w  # a new array: the in-place steps below never touch ``features``
            a += b
            np.maximum(a, 0.0, out=a)
        return np.asarray(a @ ws[-1][:, 0] + bs[-1][0], np.float32)

    @cached_property
    def _folded(self) -> tuple[tuple[NDArray[np.float32], ...], tuple[NDArray[np.float32], ...]]:
        """Layers with the standardisation folded into the first (one pass less per pixel)."""
        w0 = np.asarray(self.weights[0], np.float64)
        scale = np.asarray(self.scale, np.float64)
        first_w = (w0 / scale[:, None]).astype(np.float32)
        first_b = (self.biases[0] - (np.asarray(self.mean, np.float64) / scale) @ w0).astype(
            np.float32
        )
        return (first_w, *self.weights[1:]), (first_b, *self.biases[1:])

    def predict(self, features: ArrayLike) -> NDArray[np.float32]:
        """Sky probability of feature rows.

        Parameters
        ----------
        features : array_like, shape (n, n_features)

        Returns
        -------
        ndarray of float32, shape (n,), in [0, 1]
        """
        return np.asarray(sigmoid(self.logit(features)), np.float32)

    def predict_image(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        """Sky probability map of an upright BGR image at working resolution.

        Parameters
        ----------
        image_bgr : array_like, shape (H, W, 3), uint8

        Returns
        -------
        ndarray of float32, shape (h, w)
            ``(w, h) = predisat.sky.features.working_size((H, W), self.max_side_px)``.
        """
        small = working_image(image_bgr, self.max_side_px)
        feats = image_features(small)
        h, w = feats.shape[:2]
        return self.predict(feats.reshape(h * w, -1)).reshape(h, w)


@lru_cache(maxsize=1)
def _default_classifier() -> SkyClassifier:
    ref = resources.files("predisat") / "data" / "models" / DEFAULT_MODEL
    with resources.as_file(ref) as path:
        return SkyClassifier.load(path)


def sample_pixels(
    image_bgr: ArrayLike,
    sky: ArrayLike,
    n: int,
    rng: np.random.Generator,
    max_side_px: int = 160,
    boundary_share: float = 0.5,
    boundary_px: int = 3,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Training samples of one frame: features and 0/1 sky targets of ``n`` random pixels.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3), uint8
    sky : array_like of bool, shape (H, W)
        Reference sky (:func:`label_to_sky` of a synthetic label).
    n : int
        Pixels to draw (fewer when the working image is smaller).
    rng : numpy.random.Generator
    max_side_px : int
        Working-image size (as the classifier will use).
    boundary_share : float
        Share of the pixels drawn within ``boundary_px`` working pixels of a sky boundary.
    boundary_px : int

    Returns
    -------
    features : ndarray of float32, shape (m, n_features)
    target : ndarray of float32, shape (m,)
        The share of sky of the full-resolution pixels under each working pixel (soft at the
        boundary).
    """
    img = np.asarray(image_bgr)
    s = np.asarray(sky, bool)
    if s.shape != img.shape[:2]:
        raise ValueError(f"sky mask {s.shape} and image {img.shape[:2]} differ in size")
    small = working_image(img, max_side_px)
    h, w = small.shape[:2]
    feats = image_features(small).reshape(h * w, -1)
    # area averaging may overshoot 1 by a rounding ulp
    target = np.clip(
        cv2.resize(s.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA).ravel(), 0.0, 1.0
    )
    hard = target >= 0.5
    k = np.ones((2 * boundary_px + 1,) * 2, np.uint8)
    hm = hard.reshape(h, w).astype(np.uint8)
    near = (cv2.dilate(hm, k) != cv2.erode(hm, k)).ravel()
    n_near = min(round(n * boundary_share), int(near.sum()))
    idx_near: NDArray[np.int64] = (
        rng.choice(np.flatnonzero(near), n_near, replace=False) if n_near else np.zeros(0, int)
    )
    n_rest = min(n - n_near, h * w)
    idx_any = rng.choice(h * w, n_rest, replace=False)
    idx = np.concatenate([np.asarray(idx_near, int), idx_any])
    return feats[idx], target[idx].astype(np.float32)


def train_sky_model(
    features: ArrayLike,
    target: ArrayLike,
    hidden: tuple[int, ...] = (48, 24),
    epochs: int = 15,
    batch: int = 2048,
    learning_rate: float = 3e-3,
    l2: float = 1e-5,
    seed: int = 0,
    max_side_px: int = 160,
    card: JsonDict | None = None,
) -> SkyClassifier:
    """Train the perceptron on sky targets (0 obstacle, 1 sky, soft in between).

    Cross-entropy loss, Adam steps on shuffled mini-batches, He initialisation; every random
    draw comes from ``seed``, so the same samples give the same model.

    Parameters
    ----------
    features : array_like, shape (n, n_features)
    target : array_like, shape (n,)
        In [0, 1].
    hidden : tuple of int
        Hidden layer widths.
    epochs, batch : int
    learning_rate, l2 : float
        Adam step size (decayed by a cosine to 5 % over the run) and weight decay.
    seed : int
    max_side_px : int
        Working-image size the features were computed at.
    card : dict, optional
        Metadata stored with the model.

    Returns
    -------
    SkyClassifier
    """
    x = np.asarray(features, np.float32)
    y = np.asarray(target, np.float32).ravel()
    if x.ndim != 2 or x.shape[1] != len(FEATURE_NAMES) or y.shape[0] != x.shape[0]:
        raise ValueError(
            f"features must be (n, {len(FEATURE_NAMES)}) and target (n,), got {x.shape}, "
            f"{y.shape}"
        )
    if x.shape[0] < 10 or np.any((y < 0) | (y > 1)):
        raise ValueError("need at least 10 samples and targets in [0, 1]")
    rng = np.random.default_rng(seed)
    mean = x.mean(axis=0)
    scale = np.maximum(x.std(axis=0), 1e-6).astype(np.float32)
    xs = (x - mean) / scale
    sizes = [x.shape[1], *hidden, 1]
    ws = [rng.standard_normal((a, b)).astype(np.float32) * np.sqrt(2.0 / a)
          for a, b in itertools.pairwise(sizes)]
    bs = [np.zeros(b, np.float32) for b in sizes[1:]]
    params = ws + bs
    m1 = [np.zeros_like(p) for p in params]
    m2 = [np.zeros_like(p) for p in params]
    n = x.shape[0]
    steps = epochs * int(np.ceil(n / batch))
    t = 0
    for _ in range(epochs):
        order = rng.permutation(n)
        for i in range(0, n, batch):
            idx = order[i:i + batch]
            acts = [xs[idx]]
            for w, b in zip(ws[:-1], bs[:-1], strict=True):
                acts.append(np.maximum(acts[-1] @ w + b, 0.0))
            z = (acts[-1] @ ws[-1] + bs[-1])[:, 0]
            grad = ((sigmoid(z) - y[idx]) / idx.size)[:, None].astype(np.float32)
            gw: list[NDArray] = [np.empty(0)] * len(ws)
            gb: list[NDArray] = [np.empty(0)] * len(bs)
            for k in range(len(ws) - 1, -1, -1):
                gw[k] = acts[k].T @ grad + l2 * ws[k]
                gb[k] = grad.sum(axis=0)
                if k:
                    grad = (grad @ ws[k].T) * (acts[k] > 0)
            t += 1
            lr = learning_rate * (0.05 + 0.95 * 0.5 * (1 + np.cos(np.pi * t / steps)))
            for j, (p, g) in enumerate(zip(params, gw + gb, strict=True)):
                m1[j] = 0.9 * m1[j] + 0.1 * g
                m2[j] = 0.999 * m2[j] + 0.001 * g * g
                step = m1[j] / (1 - 0.9**t) / (np.sqrt(m2[j] / (1 - 0.999**t)) + 1e-8)
                p -= (lr * step).astype(np.float32)  # in place: params alias ws and bs
    meta = dict(card or {})
    meta.update(hidden=list(hidden), epochs=epochs, batch=batch, learning_rate=learning_rate,
                l2=l2, seed=seed, n_samples=int(n))
    return SkyClassifier(tuple(ws), tuple(bs), mean.astype(np.float32), scale, int(max_side_px),
                         FEATURE_NAMES, meta)


def guided_filter(
    guide: ArrayLike, src: ArrayLike, radius_px: int, eps: float = 1e-3, subsample: int = 1
) -> NDArray[np.float32]:
    """Edge-preserving smoothing of ``src`` steered by a grey ``guide`` (He et al. 2013).

    The output is locally an affine function of the guide, so a blurry upsampled probability
    map takes the guide's sharp edges (the skyline of the full-resolution frame).

    Parameters
    ----------
    guide : array_like, shape (H, W)
        Grey image scaled to 0-1.
    src : array_like, shape (H, W), or any 2-D shape when ``subsample > 1``
        Map to filter (a probability).
    radius_px : int
        Box radius, pixels of the guide (at least 1 at the coefficient resolution).
    eps : float
        Regularisation: edges with a guide variance below ``eps`` are smoothed away.
    subsample : int
        With ``s > 1``, the fast guided filter (He and Sun 2015, arXiv:1505.00996): the affine
        coefficients are computed at ``1/s`` resolution (box radius ``radius_px / s``) and
        upsampled bilinearly, ``s**2`` times fewer box sums; ``src`` is resampled to that grid,
        so it may be given at its own (working) resolution.

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    i = np.asarray(guide, np.float32)
    p = np.asarray(src, np.float32)
    s = int(subsample)
    if s < 1:
        raise ValueError(f"subsample must be >= 1, got {subsample}")
    if i.ndim != 2 or p.ndim != 2 or (s == 1 and i.shape != p.shape):
        raise ValueError(f"guide {i.shape} and src {p.shape} must be equal 2-D shapes")
    h, w = i.shape
    # a resampled src must show the same frame: same aspect ratio within a pixel of rounding
    if s > 1 and abs(p.shape[0] * w - p.shape[1] * h) > max(h, w):
        raise ValueError(
            f"src {p.shape} must have the aspect ratio of guide {i.shape} (the same frame at "
            "another resolution)"
        )
    if s > 1:
        size = (max(1, round(w / s)), max(1, round(h / s)))
        i_low = cv2.resize(i, size, interpolation=cv2.INTER_AREA)
        p_low = cv2.resize(p, size, interpolation=cv2.INTER_AREA if p.shape[1] > size[0]
                           else cv2.INTER_LINEAR)  # fmt: skip
        r = max(1, round(radius_px / s))
    else:
        i_low, p_low, r = i, p, int(radius_px)
    k = (2 * r + 1,) * 2

    def box(a: NDArray) -> NDArray:
        return np.asarray(cv2.boxFilter(a, cv2.CV_32F, k, borderType=cv2.BORDER_REFLECT))

    mi, mp = box(i_low), box(p_low)
    a = (box(i_low * p_low) - mi * mp) / (box(i_low * i_low) - mi * mi + eps)
    b = mp - a * mi
    ma, mb = box(a), box(b)
    if s > 1:
        ma = cv2.resize(ma, (w, h), interpolation=cv2.INTER_LINEAR)
        mb = cv2.resize(mb, (w, h), interpolation=cv2.INTER_LINEAR)
    # ma * i + mb in place: the same float32 product and sum, no full-frame temporaries
    np.multiply(ma, i, out=ma)
    ma += mb
    return ma


def sky_probability(
    image_bgr: ArrayLike,
    classifier: SkyModel | None = None,
    circle_px: tuple[float, float, float] | None = None,
    refine: bool = True,
) -> NDArray[np.float32]:
    """Full-resolution sky probability of a frame.

    The classifier runs at working resolution; the map is upsampled bilinearly and, with
    ``refine``, sharpened on the frame's edges by a :func:`guided_filter` (its fast variant,
    coefficients at half resolution, on frames at least twice the working size).

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3), uint8
        An upright frame (sky toward the top), or an upward fisheye photo when ``circle_px``
        is given.
    classifier : SkyModel, optional
        Default: :meth:`SkyClassifier.default`.
    circle_px : (cx, cy, radius), optional
        Lens circle of an upward fisheye: the photo is unwrapped to polar coordinates (zenith
        on the top row, azimuth along the columns), classified there, and wrapped back.
    refine : bool
        Apply the guided filter.

    Returns
    -------
    ndarray of float32, shape (H, W), in [0, 1]
    """
    clf = classifier or SkyClassifier.default()
    img = np.ascontiguousarray(np.asarray(image_bgr, np.uint8))
    h, w = img.shape[:2]
    scale = max(h, w) / clf.max_side_px
    refine = refine and scale > 1.0
    # Fast guided filter on frames at least twice the working size: the coefficients at half
    # resolution cost a quarter of the box sums and keep the guide's full-resolution edges.
    sub = 2 if scale >= 2.0 else 1
    if circle_px is None:
        p_small = clf.predict_image(img)
        if refine and sub > 1:  # the filter resamples the working map itself
            prob = np.asarray(p_small, np.float32)
        else:
            prob = np.asarray(
                cv2.resize(p_small, (w, h), interpolation=cv2.INTER_LINEAR), np.float32
            )
    else:
        cx, cy, r = (float(v) for v in circle_px)
        n_r, n_a = max(16, round(r)), max(32, round(np.pi * r))
        # warpPolar: rows = angle, columns = radius; transposed, the zenith is the top row.
        polar = cv2.warpPolar(img, (n_r, n_a), (cx, cy), r, cv2.WARP_POLAR_LINEAR)
        upright = np.ascontiguousarray(polar.transpose(1, 0, 2))
        p_up = clf.predict_image(upright)
        p_polar = cv2.resize(p_up, (n_a, n_r), interpolation=cv2.INTER_LINEAR).T
        prob = np.asarray(cv2.warpPolar(
            np.ascontiguousarray(p_polar), (w, h), (cx, cy), r,
            cv2.WARP_POLAR_LINEAR | cv2.WARP_INVERSE_MAP | cv2.WARP_FILL_OUTLIERS,
        ), np.float32)
        yy, xx = np.ogrid[:h, :w]
        # Outside the circle warpPolar may leave memory unset: no sky there.
        prob = np.where((xx - cx) ** 2 + (yy - cy) ** 2 < r * r, prob, 0.0).astype(np.float32)
    if refine:
        # float32(grey) / float32(255) in one pass (the same quotient as astype, then divide)
        grey = np.divide(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), np.float32(255.0),
                         dtype=np.float32)  # fmt: skip
        prob = guided_filter(grey, prob, max(2, round(1.5 * scale)), 1e-3, subsample=sub)
    # every branch above made prob a new array: clipped in place
    return np.clip(prob, 0.0, 1.0, out=prob)
