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
    """

    name: str
    albedo_rgb: tuple[float, float, float]
    texture: str
    blocks_lband: bool = True
    thin: bool = False
    width_m: float = float("inf")


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
)
"""Materials of the synthetic world; a face's material id indexes this tuple."""

MATERIAL_IDS: dict[str, int] = {m.name: i for i, m in enumerate(MATERIALS)}
"""Index in :data:`MATERIALS` of each material name."""


def material_id(name: str) -> int:
    """Index in :data:`MATERIALS` of the material called ``name``."""
    if name not in MATERIAL_IDS:
        raise KeyError(f"unknown material {name!r}; known: {sorted(MATERIAL_IDS)}")
    return MATERIAL_IDS[name]
