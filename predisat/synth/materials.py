"""Materials of the synthetic world: appearance and radio behaviour of its surfaces.

A face of a :class:`predisat.synth.world.World` carries a material id, an index into
:data:`MATERIALS`. Kept apart from the world (which needs trimesh) so that reading a simulated
run's reflections (``locator.sim.simfile``) needs no renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MATERIALS", "MATERIAL_IDS", "Material", "material_id"]


@dataclass(frozen=True)
class Material:
    """Appearance and radio behaviour of a surface.

    Attributes
    ----------
    name : str
    albedo_rgb : tuple of float, shape (3,)
        Diffuse reflectance in linear RGB, 0-1.
    texture : str
        Hint for the renderer (``"grass"``, ``"brick"``, ``"foliage"``, ...).
    blocks_lband : bool
        True when the surface blocks GNSS L-band signals.
    thin : bool
        True for thin structures (wires, thin tubes), labelled separately by the renderer; the
        camera's L-band-only views leave them out.
    width_m : float
        Physical width of a thin structure of this material, metres (the widest the scenery
        builds: its safe side): the ground truth counts it transparent only where it is
        within the first Fresnel zone rule (:func:`predisat.gnss.fresnel.transparent`) at its
        distance from the antenna. ``inf`` for the others.
    f0 : float
        Mirror reflectance at normal incidence (glass 0.04-0.25, water 0.02); the renderer
        raises it toward 1 at grazing incidence (Schlick's approximation of the Fresnel
        equations) and shows the sky, or the scenery, along the mirrored ray. 0: no mirror.
    tint_rgb : tuple of float, shape (3,)
        Colour of the mirrored light (coated glass is blue-green or bronze).
    ripple_rad : float
        Standard deviation of the surface normal's tilt, radians (water, wet ground: the
        reflection comes out rippled and blurred).
    """

    name: str
    albedo_rgb: tuple[float, float, float]
    texture: str
    blocks_lband: bool = True
    thin: bool = False
    width_m: float = float("inf")
    f0: float = 0.0
    tint_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ripple_rad: float = 0.0


MATERIALS: tuple[Material, ...] = (
    Material("grass", (0.10, 0.17, 0.05), "grass"),
    Material("ballast", (0.22, 0.20, 0.18), "gravel"),
    Material("platform", (0.40, 0.38, 0.35), "concrete"),
    Material("brick", (0.35, 0.14, 0.08), "brick"),
    Material("plaster", (0.60, 0.55, 0.45), "plaster"),
    Material("roof_tiles", (0.30, 0.10, 0.06), "tiles"),
    Material("canopy", (0.45, 0.47, 0.50), "metal"),
    Material("steel", (0.25, 0.27, 0.28), "metal"),
    # widths as scenery.build_catenary builds them: contact wire 12 mm, messenger 15 mm,
    # cantilever arm and strut 0.06 m beams
    Material("wire", (0.12, 0.10, 0.08), "wire", blocks_lband=False, thin=True, width_m=0.015),
    Material("cantilever", (0.30, 0.30, 0.30), "metal", blocks_lband=False, thin=True,
             width_m=0.06),
    Material("foliage", (0.05, 0.12, 0.03), "foliage"),
    Material("bark", (0.12, 0.09, 0.06), "bark"),
    Material("rock", (0.38, 0.34, 0.28), "rock"),
    Material("concrete", (0.45, 0.44, 0.42), "concrete"),
    Material("hills", (0.09, 0.15, 0.05), "grass"),
    # the out-of-distribution surfaces (issue 30): glass curtain walls and windows mirror the
    # sky, pale facades look like an overcast sky, water and wet ground mirror the sky and
    # the scenery; all of them block L-band like any building or ground
    Material("glass", (0.025, 0.03, 0.035), "glass", f0=0.18, tint_rgb=(0.75, 0.92, 0.95)),
    Material("white_facade", (0.82, 0.82, 0.79), "white"),
    Material("water", (0.02, 0.03, 0.03), "water", f0=0.02, ripple_rad=0.04),
    Material("wet_platform", (0.20, 0.19, 0.18), "concrete", f0=0.02, ripple_rad=0.015),
    Material("wet_ballast", (0.12, 0.11, 0.10), "gravel", f0=0.02, ripple_rad=0.06),
    # lattice pylons: legs and bracing are angle sections, thin for the Fresnel rule (a leg of
    # 0.2 m blocks within 21 m of the antenna, a brace of 0.08 m within 3.4 m); conductors
    Material("lattice_leg", (0.30, 0.31, 0.30), "metal", blocks_lband=False, thin=True,
             width_m=0.2),
    Material("lattice", (0.30, 0.31, 0.30), "metal", blocks_lband=False, thin=True,
             width_m=0.08),
    Material("conductor", (0.15, 0.15, 0.15), "wire", blocks_lband=False, thin=True,
             width_m=0.035),
)
"""Materials of the synthetic world; a face's material id indexes this tuple."""

MATERIAL_IDS: dict[str, int] = {m.name: i for i, m in enumerate(MATERIALS)}
"""Index in :data:`MATERIALS` of each material name."""


def material_id(name: str) -> int:
    """Index in :data:`MATERIALS` of the material called ``name``."""
    if name not in MATERIAL_IDS:
        raise KeyError(f"unknown material {name!r}; known: {sorted(MATERIAL_IDS)}")
    return MATERIAL_IDS[name]
