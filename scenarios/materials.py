"""Built-in material catalogue (SI units: Pa, -, kg/m^3, yield stress Pa).

Values are typical room-temperature handbook values:
- steel: E = 210 GPa, nu = 0.3, rho = 7800 (the paper's worked case), with the yield stress of hardened bearing
  steel (below): the steel of balls and hardened parts.
- structural-steel: S355 (EN 10025-2), E = 210 GPa, nu = 0.3, rho = 7850: the steel of beams and plates.
- aluminium: 6061-T6, E = 68.9 GPa, nu = 0.33, rho = 2700 (ASM Aerospace Specification Metals).
- titanium: Ti-6Al-4V, E = 113.8 GPa, nu = 0.342, rho = 4430 (ASM Aerospace Specification Metals).
- glass: soda-lime, E = 72 GPa, nu = 0.22, rho = 2500 (Shelby, Introduction to Glass Science).
- tungsten-carbide: WC-Co (6 % Co), E = 614 GPa, nu = 0.22, rho = 15000 (manufacturer data sheets).
- pmma: acrylic, E = 3.1 GPa, nu = 0.37, rho = 1190 (Ashby, Materials Selection).

Yield stress Y (uniaxial; the validity check flags a contact whose peak pressure exceeds 1.6 Y):
- steel: 2.0 GPa, hardened bearing steel AISI 52100 (~60 HRC; ASM Handbook Vol. 1, typical 1.7-2.0 GPa);
- structural-steel: 355 MPa, S355 (EN 10025-2, minimum yield strength up to 16 mm thickness): a structural
  grade yields at a contact pressure ~5.6x lower than bearing steel (round 20: a steel cantilever hit by a
  glass ball at p0 = 1.15 GPa, 2x the 0.57 GPa at which S355 yields, got no warning as "steel").
- aluminium: 276 MPa, 6061-T6 (ASM Aerospace Specification Metals).
- titanium: 880 MPa, Ti-6Al-4V annealed (ASM Aerospace Specification Metals).
- pmma: 70 MPa, tensile yield (Ashby, Materials Selection: 54-72 MPa).
- glass, tungsten-carbide: none (brittle: they crack before they yield; cracking is not checked).
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Material:
    """An isotropic linear-elastic material: `young` [Pa], `poisson` [-], `density` [kg/m^3], and
    `yield_stress` [Pa] (None: not checked, e.g. brittle materials); `source` says where the values come
    from (not part of the scene's identity: repr and equality ignore it)."""

    name: str
    young: float
    poisson: float
    density: float
    yield_stress: float | None = None
    source: str = field(default="", repr=False, compare=False)


BUILTIN_MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("steel", 210e9, 0.3, 7800.0, 2.0e9, source="handbook values (the paper's worked case); yield: "
                 "hardened bearing steel AISI 52100 ~60 HRC, ASM Handbook Vol. 1 (a beam or plate of structural "
                 "steel: use structural-steel)"),
        Material("structural-steel", 210e9, 0.3, 7850.0, 355e6, source="S355, EN 10025-2 (yield: minimum up to 16 mm "
                 "thickness); E, nu handbook values"),
        Material("aluminium", 68.9e9, 0.33, 2700.0, 276e6, source="6061-T6, ASM Aerospace Specification Metals"),
        Material("titanium", 113.8e9, 0.342, 4430.0, 880e6, source="Ti-6Al-4V annealed, ASM Aerospace Specification "
                 "Metals"),
        Material("glass", 72e9, 0.22, 2500.0, source="soda-lime, Shelby, Introduction to Glass Science"),
        Material("tungsten-carbide", 614e9, 0.22, 15000.0, source="WC-Co (6 % Co), manufacturer data sheets"),
        Material("pmma", 3.1e9, 0.37, 1190.0, 70e6, source="acrylic, Ashby, Materials Selection"),
    )
}
