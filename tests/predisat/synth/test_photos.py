"""Tests of predisat.synth.photos: determinism and labels that match what was painted."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.synth import photos
from predisat.synth.photos import OBSTACLE, SKY, THIN, random_photo


def test_same_seed_same_photo_other_seed_other_photo() -> None:
    a, b, c = random_photo(11), random_photo(11), random_photo(12)
    assert np.array_equal(a.image_bgr, b.image_bgr) and np.array_equal(a.label, b.label)
    assert not np.array_equal(a.image_bgr, c.image_bgr)


@pytest.mark.parametrize("seed", range(6))
def test_labels_are_sky_thin_or_obstacle_and_sized(seed: int) -> None:
    p = random_photo(seed, size_px=(160, 120))
    assert p.image_bgr.shape == (120, 160, 3) and p.image_bgr.dtype == np.uint8
    assert p.label.shape == (120, 160)
    assert set(np.unique(p.label).tolist()) <= {OBSTACLE, THIN, SKY}


def _canvas(seed: int) -> photos._Canvas:
    c = photos._Canvas(200, 150, np.random.default_rng(seed), seed)
    photos._sky(c)
    return c


@pytest.mark.parametrize("seed", range(8))
def test_obstacle_label_is_exactly_where_obstacles_were_painted(seed: int) -> None:
    c = _canvas(seed)
    sky_rgb = c.rgb.copy()
    hor = sky_rgb[-1, 0]
    photos._buildings(c, hor)
    photos._trees(c)
    changed = np.any(c.rgb != sky_rgb, axis=2)
    # every changed pixel is labelled obstacle; unchanged pixels are sky unless an obstacle was
    # painted in exactly the sky's colour there (a mirroring window), which is still obstacle
    assert np.all(c.label[changed] == OBSTACLE)
    assert np.all(c.label[~changed & (c.label == OBSTACLE)] == OBSTACLE)
    assert np.all((c.label == SKY) <= ~changed)


def test_wires_are_thin_only_against_the_sky() -> None:
    c = _canvas(3)
    wall = c.xx > 100
    c.paint(wall, np.array([0.5, 0.4, 0.3], np.float32))
    wire = np.abs(c.yy - 40) < 1.0
    c.paint(wire, np.zeros(3, np.float32), photos.THIN)
    assert np.all(c.label[wire & ~wall] == THIN)
    assert np.all(c.label[wire & wall] == OBSTACLE)
    assert np.all(c.label[~wire & ~wall] == SKY)


def test_photos_of_one_batch_vary_in_sky_share() -> None:
    share = [float(np.mean(random_photo(s).label >= THIN)) for s in range(12)]
    assert min(share) < 0.3 and max(share) > 0.6


def test_too_small_size_is_refused() -> None:
    with pytest.raises(ValueError, match="size_px"):
        random_photo(0, size_px=(8, 8))
