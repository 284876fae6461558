"""Optical properties of snow, firn and ice as homogeneous RGB media (OPTICS.md).

Pure formulas first, preset files at the edge. Every triple is (R, G, B) = (640, 530, 470) nm and
every coefficient is per metre unless a preset says otherwise (the thesis sets, section 9).

    derive_snow(density, ssa=...)          grains of ice in air: sigma_t = rho SSA / 2, TARTES g
    derive_bubbly_ice(density, radius)     air bubbles in ice: sigma_s = 3 v / (2 r_b)
    derive_clear_ice()                     pure ice: absorption only, dielectric boundary
    thesis_set(k)                          Chukir 2021 Table 6.1/6.2, literal
    load_preset(name)                      configs/presets/optics/<name>.yaml -> MediumOptics
    reduce(optics, form)                   full | diffraction_removed | isotropic_reduced (section 4)
    derived_quantities(optics)             k_e, z_e, r_d, transport mean free path (section 5)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Literal, TypeVar

import numpy as np
import yaml

from common.paths import OPTICS_PRESETS_DIR, optics_preset_names

RHO_ICE = 917.0  # kg m-3
WAVELENGTHS_NM = (640.0, 530.0, 470.0)
# Recommended triple: Warren & Brandt 2008 at 640 nm, Picard et al. 2016 at 530/470 nm [m-1].
ALPHA_ICE = (0.240, 0.047, 0.022)
# Real index of ice, Warren & Brandt 2008.
N_ICE = (1.308, 1.312, 1.315)
# Black carbon mass absorption cross-section at 640/530/470 nm (Bond & Bergstrom 2006, ~1/lambda) [m2 kg-1].
MAC_BLACK_CARBON = (6.4e3, 7.8e3, 8.8e3)

PRESET_NAMES = ("fresh_snow", "aged_snow", "penitente_firn", "dense_firn", "bubbly_ice", "clear_ice")
THESIS_SET_NAMES = tuple(f"thesis_set_{k}" for k in range(1, 7))

Boundary = Literal["null", "dielectric"]
Form = Literal["full", "diffraction_removed", "isotropic_reduced"]
Triple = tuple[float, float, float]
T = TypeVar("T")


def _three(values: Iterable[T]) -> tuple[T, T, T]:
    """A per-channel iterable as an RGB triple (exactly three items)."""
    red, green, blue = values
    return red, green, blue


def _triple(value, name: str) -> Triple:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,))
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value}")
    return _three(float(x) for x in arr)


@dataclass(frozen=True)
class MediumOptics:
    """A homogeneous HG medium and its boundary, per RGB channel.

    ``ior`` is the refractive index of the material (ice for snow); ``boundary`` says whether a
    renderer puts a smooth dielectric at the surface (``dielectric``) or none (``null``, index
    matched: the region index is then that of the surroundings, see ``region_ior``).
    """

    sigma_s: Triple  # scattering coefficient [m-1 or per scene unit]
    sigma_a: Triple  # absorption coefficient [m-1]
    g: Triple  # Henyey-Greenstein mean cosine [-]
    ior: Triple  # material refractive index [-]
    boundary: Boundary  # null (index matched) or dielectric
    form: Form = "full"  # which phase-function parameterisation (section 4)
    name: str = ""
    source: str = ""  # one line: where the numbers come from
    inputs: Mapping[str, float | str] = field(default_factory=dict)  # physical inputs, for reports

    def __post_init__(self) -> None:
        for key in ("sigma_s", "sigma_a"):
            values = getattr(self, key)
            if len(values) != 3 or any(v < 0 for v in values):
                raise ValueError(f"{self.name or 'medium'}: {key} must be three non-negative numbers, got {values}")
        if any(not -1 < v < 1 for v in self.g):
            raise ValueError(f"{self.name or 'medium'}: g must lie in (-1, 1), got {self.g}")
        if any(v < 1 for v in self.ior):
            raise ValueError(f"{self.name or 'medium'}: ior must be >= 1, got {self.ior}")

    @property
    def sigma_t(self) -> Triple:
        return _three(s + a for s, a in zip(self.sigma_s, self.sigma_a))

    @property
    def single_scattering_albedo(self) -> Triple:
        return _three(s / t if t > 0 else 0.0 for s, t in zip(self.sigma_s, self.sigma_t))

    @property
    def render_g(self) -> float:
        """The one g a renderer with a scalar HG phase uses: the channel mean."""
        return float(np.mean(self.g))

    @property
    def render_ior(self) -> float:
        """The one index a renderer uses for refraction and OPL: green (530 nm) for dielectrics."""
        return float(self.ior[1])

    @property
    def region_ior(self) -> float:
        """Group index of the region inside the boundary: 1 (air) when index matched (render/core/DESIGN.md §1)."""
        return self.render_ior if self.boundary == "dielectric" else 1.0

    def to_dict(self) -> dict:
        out = asdict(self)
        out["inputs"] = dict(self.inputs)
        return out


# ---------------------------------------------------------------- physical derivations (sections 3, 6, 7)


def optical_radius_from_ssa(ssa: float) -> float:
    """r_opt = 3 / (rho_ice SSA) [m] from SSA [m2 kg-1]."""
    if ssa <= 0:
        raise ValueError(f"specific surface area must be positive, got {ssa} m2/kg")
    return 3.0 / (RHO_ICE * ssa)


def ssa_from_optical_radius(optical_radius: float) -> float:
    if optical_radius <= 0:
        raise ValueError(f"optical radius must be positive, got {optical_radius} m")
    return 3.0 / (RHO_ICE * optical_radius)


def impurity_absorption(
    density: float,
    black_carbon_ng_per_g: float = 0.0,
    dust_ug_per_g: float = 0.0,
    dust_mac_400: float = 83.0,
    dust_aae: float = 2.9,
) -> np.ndarray:
    """sigma_a added by impurities, rho c MAC(lambda) [m-1] (section 7).

    Black carbon in ng/g, dust in ug/g; dust MAC(lambda) = MAC_400 (lambda / 400 nm)^-AAE with MAC_400 in m2/kg
    (defaults: Patagonian PM10, Caponi et al. 2017).
    """
    lam = np.asarray(WAVELENGTHS_NM)
    bc = density * black_carbon_ng_per_g * 1e-9 * np.asarray(MAC_BLACK_CARBON)
    dust = density * dust_ug_per_g * 1e-6 * dust_mac_400 * (lam / 400.0) ** (-dust_aae)
    return bc + dust


def tartes_g(n: np.ndarray, c: np.ndarray, g0_natural: float = 0.86) -> np.ndarray:
    """TARTES 'linear' asymmetry g = g_inf - (g_inf - g0) exp(-y c); g0_natural is g0 at n = 1.3."""
    g_inf = 0.9751 - 0.105 * (n - 1.3)
    g0 = g0_natural - 0.38 * (n - 1.3)
    y = 0.728 + 0.752 * (n - 1.3)
    return g_inf - (g_inf - g0) * np.exp(-y * c)


def derive_snow(
    density: float,
    *,
    ssa: float | None = None,
    optical_radius: float | None = None,
    absorption_enhancement: float = 1.6,
    g0_natural: float = 0.86,
    black_carbon_ng_per_g: float = 0.0,
    dust_ug_per_g: float = 0.0,
    alpha_ice=ALPHA_ICE,
    n_ice=N_ICE,
    name: str = "snow",
) -> MediumOptics:
    """Snow or firn from density [kg m-3] and SSA [m2 kg-1] or optical radius [m] (section 3).

    sigma_t = 3 rho / (2 rho_ice r_opt); 1 - omega from the Kokhanovsky-Zege form (TARTES), which reduces to
    sigma_a = B (rho / rho_ice) alpha_ice; impurities add absorption only; index-matched boundary.
    """
    if not 0 < density < RHO_ICE:
        raise ValueError(f"snow density must lie in (0, {RHO_ICE}) kg/m3, got {density}")
    if ssa is not None and optical_radius is None:
        r_opt = optical_radius_from_ssa(ssa)
    elif optical_radius is not None and ssa is None:
        r_opt = float(optical_radius)
    else:
        raise ValueError("give exactly one of ssa (m2/kg) or optical_radius (m)")
    if r_opt <= 0:
        raise ValueError(f"optical radius must be positive, got {r_opt} m")
    alpha = np.asarray(alpha_ice, dtype=np.float64)
    n = np.asarray(n_ice, dtype=np.float64)
    sigma_t = 3.0 * density / (2.0 * RHO_ICE * r_opt) * np.ones(3)
    c = 2.0 * alpha * r_opt
    w = 0.0611 + 0.17 * (n - 1.3)
    one_minus_omega = 0.5 * (1 - w) * (1 - np.exp(-(2.0 / 3.0) * absorption_enhancement * c / (1 - w)))
    sigma_a_ice = sigma_t * one_minus_omega
    sigma_s = sigma_t - sigma_a_ice
    sigma_a = sigma_a_ice + impurity_absorption(density, black_carbon_ng_per_g, dust_ug_per_g)
    g = tartes_g(n, c, g0_natural)
    inputs = {
        "density_kg_m3": density,
        "ssa_m2_kg": ssa_from_optical_radius(r_opt),
        "optical_radius_m": r_opt,
        "absorption_enhancement": absorption_enhancement,
        "g0_natural": g0_natural,
        "black_carbon_ng_g": black_carbon_ng_per_g,
        "dust_ug_g": dust_ug_per_g,
    }
    return MediumOptics(
        _triple(sigma_s, "sigma_s"),
        _triple(sigma_a, "sigma_a"),
        _triple(g, "g"),
        _triple(n, "ior"),
        "null",
        "full",
        name,
        "OPTICS.md §3: grains of ice in air (Kokhanovsky & Zege 2004, TARTES)",
        inputs,
    )


def derive_bubbly_ice(
    density: float,
    bubble_radius: float,
    *,
    g: float = 0.86,
    alpha_ice=ALPHA_ICE,
    n_ice=N_ICE,
    black_carbon_ng_per_g: float = 0.0,
    dust_ug_per_g: float = 0.0,
    name: str = "bubbly_ice",
) -> MediumOptics:
    """Glacier ice with air bubbles: v = 1 - rho/rho_ice, sigma_s = 3 v / (2 r_b), sigma_a = (1 - v) alpha (section 6)."""
    if not 0 < density <= RHO_ICE:
        raise ValueError(f"ice density must lie in (0, {RHO_ICE}] kg/m3, got {density}")
    if bubble_radius <= 0:
        raise ValueError(f"bubble radius must be positive, got {bubble_radius} m")
    v = 1.0 - density / RHO_ICE
    sigma_s = 3.0 * v / (2.0 * bubble_radius) * np.ones(3)
    sigma_a = (1.0 - v) * np.asarray(alpha_ice) + impurity_absorption(density, black_carbon_ng_per_g, dust_ug_per_g)
    inputs = {
        "density_kg_m3": density,
        "air_fraction": v,
        "bubble_radius_m": bubble_radius,
        "black_carbon_ng_g": black_carbon_ng_per_g,
        "dust_ug_g": dust_ug_per_g,
    }
    return MediumOptics(
        _triple(sigma_s, "sigma_s"),
        _triple(sigma_a, "sigma_a"),
        _triple(g, "g"),
        _triple(n_ice, "ior"),
        "dielectric",
        "full",
        name,
        "OPTICS.md §6: air bubbles in ice",
        inputs,
    )


def derive_clear_ice(
    *, haze_sigma_s: float = 0.0, g: float = 0.86, alpha_ice=ALPHA_ICE, n_ice=N_ICE, name: str = "clear_ice"
) -> MediumOptics:
    """Pure ice: sigma_a = alpha_ice, optional faint grey haze, smooth dielectric (section 6)."""
    return MediumOptics(
        _triple(haze_sigma_s, "sigma_s"),
        _triple(alpha_ice, "sigma_a"),
        _triple(g, "g"),
        _triple(n_ice, "ior"),
        "dielectric",
        "full",
        name,
        "OPTICS.md §6: clear ice",
        {"haze_sigma_s_m": haze_sigma_s},
    )


def thesis_set(k: int, *, metres_per_unit: float | None = None) -> MediumOptics:
    """Thesis set k (configs/presets/optics/thesis_set_k.yaml), literal: sigma_s, sigma_a, HG g, dielectric.

    ``metres_per_unit`` rescales for a mesh converted to metres: a length of L m is L / metres_per_unit thesis
    units, so coefficients per metre are the per-unit values divided by it (optical thickness unchanged).
    """
    if k not in range(1, 7):
        raise ValueError(f"thesis sets are numbered 1-6, got {k}")
    spec = _read_preset(f"thesis_set_{k}")
    if metres_per_unit is not None:
        spec["metres_per_unit"] = metres_per_unit
    return optics_from_mapping(spec, f"thesis_set_{k}")


def _thesis_from_values(
    name: str, sigma_s, sigma_a, g: float, ior: float, metres_per_unit: float = 1.0
) -> MediumOptics:
    if metres_per_unit <= 0:
        raise ValueError(f"{name}: metres_per_unit must be positive, got {metres_per_unit}")
    scale = 1.0 / metres_per_unit
    return MediumOptics(
        _triple(np.asarray(sigma_s, dtype=np.float64) * scale, "sigma_s"),
        _triple(np.asarray(sigma_a, dtype=np.float64) * scale, "sigma_a"),
        _triple(g, "g"),
        _triple(ior, "ior"),
        "dielectric",
        "full",
        name,
        f"Chukir 2021 (OPTICS.md §9), literal, per thesis unit / {metres_per_unit} m",
        {"metres_per_unit": metres_per_unit},
    )


# ---------------------------------------------------------------- render-time reductions (section 4)


def reduce(optics: MediumOptics, form: Form) -> MediumOptics:
    """Return the medium in another phase-function form; sigma_a and sigma_s (1 - g) are unchanged.

    diffraction_removed: sigma_s / 2 with g_G = 2 g - 1; isotropic_reduced: sigma_s (1 - g) with g = 0.
    Only a medium in the full form can be reduced (reducing twice would double-count).
    """
    if form == optics.form:
        return optics
    if optics.form != "full":
        raise ValueError(f"{optics.name}: cannot turn the {optics.form} form into {form}; start from the full form")
    s = np.asarray(optics.sigma_s)
    g = np.asarray(optics.g)
    if form == "diffraction_removed":
        sigma_s, g_new = s / 2.0, 2.0 * g - 1.0
    elif form == "isotropic_reduced":
        sigma_s, g_new = s * (1.0 - g), np.zeros(3)
    else:
        raise ValueError(f"unknown medium form {form!r}; use full, diffraction_removed or isotropic_reduced")
    return replace(optics, sigma_s=_triple(sigma_s, "sigma_s"), g=_triple(g_new, "g"), form=form)


# ---------------------------------------------------------------- derived quantities (section 5)


@dataclass(frozen=True)
class DerivedOptics:
    """Asymptotic quantities of the bare semi-infinite, index-matched medium, per channel."""

    sigma_t: Triple  # [m-1]
    single_scattering_albedo: Triple  # [-]
    reduced_scattering: Triple  # sigma_s (1 - g) [m-1]
    flux_extinction: Triple  # k_e [m-1]
    efolding_depth: Triple  # z_e = 1 / k_e, or 1 / sigma_t without scattering [m]
    diffuse_albedo: Triple  # r_d (white-sky) from the asymptotic formula, NaN without scattering [-]
    transport_mean_free_path: Triple  # 1 / (sigma_s (1 - g)) [m], inf without scattering
    diffusive: tuple[bool, bool, bool]  # sigma_a < 0.1 sigma_s': there r_d and k_e are accurate to < 0.01
    slab_transmittance_1m: Triple  # unscattered T of a 1 m slab at normal incidence, incl. Fresnel if dielectric

    def to_dict(self) -> dict:
        return {
            k: [None if isinstance(x, float) and not math.isfinite(x) else x for x in v]
            for k, v in asdict(self).items()
        }


def derived_quantities(optics: MediumOptics) -> DerivedOptics:
    """k_e = sqrt(3 sigma_a (sigma_a + sigma_s')), z_e = 1/k_e, r_d = exp(-4 sqrt(sigma_a / (3 (sigma_a + sigma_s'))))."""
    s = np.asarray(optics.sigma_s)
    a = np.asarray(optics.sigma_a)
    g = np.asarray(optics.g)
    t = s + a
    s_red = s * (1.0 - g)
    k_e = np.sqrt(3.0 * a * (a + s_red))
    diffusive = a < 0.1 * s_red
    with np.errstate(divide="ignore", invalid="ignore"):
        # Without scattering light simply decays along the beam: the e-folding depth is 1 / sigma_t.
        z_e = np.where(s_red > 0, 1.0 / k_e, 1.0 / t)
        r_d = np.where(s_red > 0, np.exp(-4.0 * np.sqrt(a / (3.0 * (a + s_red)))), np.nan)
        ell = np.where(s_red > 0, 1.0 / s_red, np.inf)
        omega = np.where(t > 0, s / t, 0.0)
    n = np.asarray(optics.ior)
    fresnel_r0 = ((n - 1) / (n + 1)) ** 2 if optics.boundary == "dielectric" else np.zeros(3)
    slab_t = (1 - fresnel_r0) ** 2 * np.exp(-t * 1.0)

    def floats(x) -> Triple:
        return _three(float(v) for v in x)

    return DerivedOptics(
        floats(t),
        floats(omega),
        floats(s_red),
        floats(k_e),
        floats(z_e),
        floats(r_d),
        floats(ell),
        _three(bool(x) for x in diffusive),
        floats(slab_t),
    )


# ---------------------------------------------------------------- presets on disk


def preset_path(name: str) -> Path:
    return OPTICS_PRESETS_DIR / f"{name}.yaml"


def available_presets() -> list[str]:
    return optics_preset_names()


def optics_from_mapping(spec: Mapping, name: str) -> MediumOptics:
    """Build a medium from a preset-style mapping: ``kind`` snow | bubbly_ice | clear_ice | thesis | coefficients."""
    spec = dict(spec)
    kind = spec.pop("kind", None)
    spec.pop("description", None)
    try:
        if kind == "snow":
            return derive_snow(name=name, **spec)
        if kind == "bubbly_ice":
            return derive_bubbly_ice(name=name, **spec)
        if kind == "clear_ice":
            return derive_clear_ice(name=name, **spec)
        if kind == "thesis":
            return _thesis_from_values(name, **spec)
        if kind == "coefficients":
            ior = spec.get("ior", 1.0)
            return MediumOptics(
                _triple(spec["sigma_s"], "sigma_s"),
                _triple(spec["sigma_a"], "sigma_a"),
                _triple(spec.get("g", 0.0), "g"),
                _triple(ior, "ior"),
                spec.get("boundary", "null"),
                "full",
                name,
                spec.get("source", "explicit coefficients"),
            )
    except TypeError as exc:
        raise ValueError(f"optical preset '{name}': {exc}") from None
    raise ValueError(
        f"optical preset '{name}': kind must be snow, bubbly_ice, clear_ice, thesis or coefficients, got {kind!r}"
    )


def _read_preset(name: str) -> dict:
    path = preset_path(name)
    if not path.is_file():
        raise ValueError(f"unknown optical preset '{name}' (no {path}); available: {', '.join(available_presets())}")
    spec = yaml.safe_load(path.read_text(encoding="utf-8"))
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: an optical preset must be a YAML mapping")
    return spec


def load_preset(name: str) -> MediumOptics:
    """Read ``configs/presets/optics/<name>.yaml`` and derive its medium (full form)."""
    return optics_from_mapping(_read_preset(name), name)


def preset_description(name: str) -> str:
    spec = yaml.safe_load(preset_path(name).read_text(encoding="utf-8"))
    return str(spec.get("description", ""))


__all__ = [
    "ALPHA_ICE",
    "N_ICE",
    "RHO_ICE",
    "WAVELENGTHS_NM",
    "PRESET_NAMES",
    "THESIS_SET_NAMES",
    "MediumOptics",
    "DerivedOptics",
    "derive_snow",
    "derive_bubbly_ice",
    "derive_clear_ice",
    "thesis_set",
    "reduce",
    "derived_quantities",
    "impurity_absorption",
    "tartes_g",
    "load_preset",
    "available_presets",
    "optics_from_mapping",
    "optical_radius_from_ssa",
    "ssa_from_optical_radius",
]
