"""The sky segmentation network: a small U-Net, run by OpenCV's DNN module from an ONNX file.

The per-pixel perceptron of :mod:`predisat.sky.perceptron` decides from local colour and texture, so
a light facade or a snow field that looks like sky locally is sky to it. A convolutional
network sees the context (a window grid, a ridge above the snow). The shipped network
``predisat/data/models/sky_unet.onnx`` (its card, with the training data, seeds and held-out
scores, in ``sky_unet.json`` beside it) is trained by ``scripts/train_sky_cnn.py`` with
PyTorch on data the project makes itself: procedural photos (:mod:`predisat.synth.photos`) and
rendered survey frames (:mod:`predisat.synth.generate`). Inference needs only OpenCV and numpy
(no PyTorch, no network).

Input of the network: the image resized to ``input_px`` x ``input_px`` (aspect not kept), BGR
scaled to ``[-0.5, 0.5]``, plus a fourth channel holding the row position (0 top, 1 bottom).
Output: the sky logit at the same size. Images much wider than tall (an unwrapped fisheye
panorama) are split into near-square tiles.

>>> net = SkyNet.default()
>>> prob = net.predict_image(cv2.imread("frame.jpg"))   # (h, w) at working resolution
"""

from __future__ import annotations

import itertools
import json
import os
import threading
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky.features import working_size
from predisat.sky.perceptron import SkyClassifier, SkyModel, sigmoid

if TYPE_CHECKING:  # an alias only: the segmentation loads no module outside predisat.sky
    from predisat.jsontypes import JsonDict

__all__ = ["DEFAULT_NET", "NET_METHODS", "SkyEnsemble", "SkyNet", "classifier_with_net",
           "network_input"]

DEFAULT_NET = "sky_unet.onnx"
#: The segmentation methods that run a network (and can run a candidate instead of the shipped one).
NET_METHODS = ("cnn", "ensemble")
_FORMAT = "predisat-sky-unet"


def network_input(image_bgr: ArrayLike, input_px: int) -> NDArray[np.float32]:
    """The network's input blob of one upright BGR image.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3), uint8
    input_px : int
        Side of the square input.

    Returns
    -------
    ndarray of float32, shape (1, 4, input_px, input_px)
        B, G, R in ``[-0.5, 0.5]`` and the row position in ``[0, 1]``.
    """
    img = np.asarray(image_bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image_bgr must be an (H, W, 3) uint8 image, got {img.shape} {img.dtype}")
    s = int(input_px)
    x = cv2.resize(np.ascontiguousarray(img), (s, s), interpolation=cv2.INTER_AREA)
    x = x.astype(np.float32) / 255.0 - 0.5
    row = np.broadcast_to(np.linspace(0.0, 1.0, s, dtype=np.float32)[:, None], (s, s))
    return np.ascontiguousarray(np.concatenate([x.transpose(2, 0, 1), row[None]])[None])


# One network object per thread, process and file version: cv2.dnn.Net cannot be pickled or
# shared, and is not thread-safe either (setInput then forward): a `dask worker` started as
# docs/cluster.md says runs one thread per core in one process, and two threads sharing one
# net failed 20 of 202 frames with OpenCV assertions and segmented 7 more with another
# frame's input, exit 0 (a user trial). A file replaced since (retrained, copied over) is
# read again.
_NETS = threading.local()
_NETS_PER_THREAD = 4


def _load_net(path: str) -> Any:
    st = os.stat(path)
    key = (path, st.st_mtime_ns, st.st_size, st.st_ino)
    nets: dict[tuple[str, int, int, int], Any] | None = getattr(_NETS, "nets", None)
    if nets is None:
        nets = _NETS.nets = {}
    if key not in nets:
        if len(nets) >= _NETS_PER_THREAD:
            nets.clear()
        nets[key] = _read_net(path)
    return nets[key]


def _read_net(path: str) -> Any:
    try:
        return cv2.dnn.readNetFromONNX(path)
    except cv2.error as exc:
        raise ValueError(
            f"sky network {path} is not a readable ONNX file ({str(exc).strip()[:200]}); "
            "reinstall the package or retrain it with scripts/train_sky_cnn.py"
        ) from None


@dataclass(frozen=True)
class SkyNet:
    """A trained sky segmentation network (ONNX file) and its card.

    Attributes
    ----------
    path : Path
        The ONNX file.
    input_px : int
        Side of the square network input.
    card : dict
        Training metadata (data, seeds, parameters, held-out scores).
    mirror : bool
        Average the probability of each image with that of its mirror image (test-time
        augmentation: twice the network time; fewer skyline errors on cloudy validation
        frames, ``docs/segmentation.md``).
    """

    path: Path
    input_px: int = 128
    card: JsonDict = field(default_factory=dict, compare=False)
    mirror: bool = True

    def __post_init__(self) -> None:
        if self.input_px < 16 or self.input_px % 16:
            raise ValueError(f"input_px must be a multiple of 16, >= 16, got {self.input_px}")

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> SkyNet:
        """Read a network: the ONNX file and its card (same name, ``.json``)."""
        p = Path(path)
        card_path = p.with_suffix(".json")
        for f in (p, card_path):
            if not f.is_file():
                raise FileNotFoundError(
                    f"sky network file {f} does not exist; train it with scripts/train_sky_cnn.py"
                )
        card = json.loads(card_path.read_text(encoding="utf-8"))
        if card.get("format") != _FORMAT:
            raise ValueError(
                f"{card_path} is not a PREDISAT sky network card (format {card.get('format')!r})"
            )
        if not isinstance(card.get("input_px"), int):
            raise ValueError(
                f"{card_path} has no integer 'input_px' (the network's input side); "
                "retrain with scripts/train_sky_cnn.py"
            )
        return cls(p, int(card["input_px"]), card)

    @classmethod
    def default(cls) -> SkyNet:
        """The network shipped in ``predisat/data/models``."""
        return _default_net()

    @property
    def max_side_px(self) -> int:
        """Longest side of the probability map of an image (sets the guided filter's radius)."""
        return self.input_px

    def _logits(self, blob: NDArray[np.float32]) -> NDArray[np.float32]:
        """Sky logits of a batch of network inputs, ``(n, input_px, input_px)``."""
        net = _load_net(str(self.path))
        net.setInput(blob)
        out = np.asarray(net.forward(), np.float32)
        return out.reshape(-1, self.input_px, self.input_px)

    def logit_tile(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        """Sky logit of one image at the network's size, ``(input_px, input_px)``."""
        return self._logits(network_input(image_bgr, self.input_px))[0]

    def probability_tile(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        """Sky probability of one image at the network's size, ``(input_px, input_px)``.

        With ``mirror``, the mean of the probabilities of the image and of its mirror image
        (mirrored back), from one forward pass of a batch of two.
        """
        img = np.asarray(image_bgr)
        s = self.input_px
        blob = network_input(img, s)
        if self.mirror:
            blob = np.concatenate([blob, network_input(img[:, ::-1], s)])
        prob = sigmoid(self._logits(blob))
        if self.mirror:
            return np.asarray(0.5 * (prob[0] + prob[1][:, ::-1]), np.float32)
        return np.asarray(prob[0], np.float32)

    def predict_image(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        """Sky probability map of an upright BGR image at working resolution.

        Parameters
        ----------
        image_bgr : array_like, shape (H, W, 3), uint8

        Returns
        -------
        ndarray of float32, shape (h, w)
            ``(w, h) = predisat.sky.features.working_size((H, W), input_px)``; for an image
            wider than 1.5 times its height, cut into ``n = round(W / H)`` tiles,
            ``working_size((H, W), n * input_px)``.
        """
        img = np.asarray(image_bgr)
        h, w = img.shape[:2]
        n_tiles = max(1, round(w / h)) if w > 1.5 * h else 1
        edges = np.linspace(0, w, n_tiles + 1).round().astype(int)
        prob = np.hstack(
            [self.probability_tile(img[:, a:b]) for a, b in itertools.pairwise(edges)]
        )
        size = working_size(img.shape, self.input_px * n_tiles)
        return np.asarray(cv2.resize(prob, size, interpolation=cv2.INTER_LINEAR), np.float32)


@dataclass(frozen=True)
class SkyEnsemble:
    """Mean sky probability of several models (the perceptron and the network by default).

    The two models fail on different things (``docs/segmentation.md``): the perceptron, on
    local colour and texture, takes light facades for sky; the network, on context, misses some
    deep blue or stormy skies. Their mean is better than either on real photos.

    Attributes
    ----------
    members : tuple
        Objects with ``predict_image(image_bgr) -> (h, w) probability`` and ``max_side_px``.
    weights : tuple of float
        One per member (normalised to sum 1).
    """

    members: tuple[SkyModel, ...]
    weights: tuple[float, ...]

    def __post_init__(self) -> None:
        if not self.members or len(self.members) != len(self.weights):
            raise ValueError("need one weight per member, and at least one member")
        if any(w < 0 for w in self.weights) or sum(self.weights) <= 0:
            raise ValueError(f"weights must be >= 0 with a positive sum, got {self.weights}")

    @classmethod
    def default(cls) -> SkyEnsemble:
        """The shipped perceptron and network, weighted equally."""
        return cls.with_net(SkyNet.default())

    @classmethod
    def with_net(cls, net: SkyNet) -> SkyEnsemble:
        """The shipped perceptron and another network (a candidate), weighted equally."""
        return cls((SkyClassifier.default(), net), (0.5, 0.5))

    @property
    def max_side_px(self) -> int:
        """The finest member's working size."""
        return max(int(m.max_side_px) for m in self.members)

    def predict_image(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        """Weighted mean probability, on the finest member's working grid, ``(h, w)``."""
        maps = [np.asarray(m.predict_image(image_bgr), np.float32) for m in self.members]
        h, w = max((p.shape for p in maps), key=lambda s: s[0] * s[1])
        total = sum(self.weights)
        out = np.zeros((h, w), np.float32)
        for p, wt in zip(maps, self.weights, strict=True):
            if p.shape != (h, w):
                p = np.asarray(cv2.resize(p, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)
            out += np.float32(wt / total) * p
        return out


def classifier_with_net(method: str, net: SkyNet) -> SkyNet | SkyEnsemble:
    """The probability model of a segmentation method with ``net`` as its network.

    Parameters
    ----------
    method : {"cnn", "ensemble"}
        ``"cnn"``: the network alone; ``"ensemble"``: :meth:`SkyEnsemble.with_net`.
    net : SkyNet
        A candidate network (:meth:`SkyNet.load`).

    Returns
    -------
    SkyNet or SkyEnsemble
        For ``predisat.sky.segment.segment_sky(..., classifier=)``.
    """
    if method not in NET_METHODS:
        raise ValueError(
            f"method {method!r} runs no network, so a sky network {net.path} has no use there; "
            f"choose one of {NET_METHODS} (CLI: --method / --segmenter ensemble)"
        )
    return net if method == "cnn" else SkyEnsemble.with_net(net)


@lru_cache(maxsize=1)
def _default_net() -> SkyNet:
    ref = resources.files("predisat") / "data" / "models" / DEFAULT_NET
    with resources.as_file(ref) as path:
        return SkyNet.load(path)
