"""LAMMPS-specific numbers: what ``pair_style granular`` and ``fix wall/gran granular`` must be
given so that they deliver the case's physics (every other number comes from
:func:`orchestrator.derive.derive`, shared by all engines).

Sources (LAMMPS 22 Jul 2025, ``src/GRANULAR``):

- ``hertz/material E e ν`` between two particles of one material: F = 4/3 E* √R δ^(3/2) with
  E* = E/(2(1-ν²)) (``GranSubMod::mix_stiffnessE``); against a ``fix wall/gran`` wall the same
  E/(2(1-ν²)) of the numbers given to the fix (``mix_stiffnessE_wall``: the wall is taken to be
  of the particle's material). A wall of another material is therefore given the E' that makes
  E'/(2(1-ν²)) the case's particle-wall E* (:func:`wall_young`). The 2021 Debian build used
  E/(2(1-ν)) there, 7.6 % too stiff at ν = 0.2; the 2025 wheel does not (checked by the
  Chung & Ooi sphere-plane cases, whose contact times agree with Hertz to 1e-4);
- ``tangential mindlin k_t x_γt μ``: F_t = -min(μ F_n, |k_t a ξ + η_t v_t|) with the contact
  radius a = √(R δ) and the total tangential displacement ξ, k_t = 8 G* (given explicitly);
  the same no-slip Mindlin stiffness and total-displacement history as LIGGGHTS' ``tangential
  history`` (Chung & Ooi 2011's "Mindlin" is the no-slip k_t = 8 G* a);
- ``damping coeff_restitution`` (``GranSubModDampingCoeffRestitution``): η_n = 2√(5/6)(-β)
  √(m* S_n), S_n = 2 E* a, β = ln e/√(ln²e + π²): LIGGGHTS' and YADE's Tsuji form; with
  ``limit_damping`` the total normal force is clipped at zero as LIGGGHTS' ``limitForce on``,
  so the same inverse (:func:`orchestrator.contact_law.restitution_input`) delivers the requested e;
- tangential damping η_t = x_γt η_n: LIGGGHTS uses η_t = 2√(5/6)(-β)√(m* S_t), S_t = 8 G* a,
  so x_γt = √(S_t/S_n) = √(4 G*/E*) (:func:`tangential_damping_factor`);
- ``damping viscoelastic``: η_n = η_n0 a m* (Brilliantov et al. 1996): the damping force
  η_n0 m* √R √δ δ̇ is seed 000 eq. 1's γ_n √ξ ξ̇ when η_n0 = γ_n/(m* √R*) (:func:`viscoelastic_eta`).
"""
from __future__ import annotations

import math

import numpy as np

from orchestrator.contact_law import DerivationError, restitution_input


def wall_young(E_eff_target: float, nu: float) -> float:
    """Young's modulus [Pa] to give ``fix wall/gran granular hertz/material E' e ν`` so that its
    E'/(2(1-ν²)) equals ``E_eff_target`` [Pa], the case's particle-wall E*."""
    return 2.0 * (1.0 - nu * nu) * E_eff_target


def tangential_damping_factor(E_eff: float, G_eff: float) -> float:
    """x_γt = η_t/η_n = √(S_t/S_n) = √(8 G* a/(2 E* a)) = √(4 G*/E*) [-]: LAMMPS' tangential
    damping equal to LIGGGHTS' (normal_model_hertz.h: γ_t = -2√(5/6) β √(S_t m*))."""
    return math.sqrt(4.0 * G_eff / E_eff)


def restitution_damping(params: dict) -> dict:
    """``damping coeff_restitution`` input: {``e_input``, ``limit_damping``}. With tensile clipping
    (``limit_damping``) the e that LIGGGHTS is fed (the clipped law's inverse); below what the
    clipped law can deliver (``engine_input`` 0) the unclipped law is used and fed the target
    itself, as YADE is (Antypov & Elliott 2011, eq. 17)."""
    target = params["restitution"]["target"]
    if target >= 1.0:
        return {"e_input": 1.0, "limit_damping": True}
    try:
        return {"e_input": restitution_input(target), "limit_damping": True}
    except DerivationError:      # below what the clipped law delivers at all
        return {"e_input": target, "limit_damping": False}


def viscoelastic_eta(gamma_n: float, m_eff: float, R_eff: float) -> float:
    """η_n0 [1/(m s)] of ``damping viscoelastic`` whose force η_n0 m* √(R* δ) δ̇ equals
    γ_n √δ δ̇ (seed 000 eq. 1) for a pair of reduced mass ``m_eff`` [kg] and radius ``R_eff`` [m]."""
    return gamma_n / (m_eff * math.sqrt(R_eff))


def seed_gamma_n(E_eff: float, m_eff: float) -> float:
    """Seed 000's normal damping constant γ_n = √(4/3 E* m*) [kg/(m^½ s)] (section 3.2)."""
    return math.sqrt(4.0 / 3.0 * E_eff * m_eff)


def rolling_twisting(contact: dict, d50: float, rho: float) -> dict:
    """``rolling sds k_r γ_r μ_r`` and ``twisting sds k_tw γ_tw μ_tw`` for seed 000's rolling and
    twisting resistance (§3.2), from a scene's contact numbers (``rolling_stiffness`` =
    ``twisting_stiffness`` = k_t r_eff², ``rolling_coefficient`` μ_r with M_max = μ_r r_eff |F_n|, ``torsion_coefficient``
    μ_tor/r_eff), for the median pair (r_eff = d50/4, m_eff = m50/2).

    LAMMPS (``gran_sub_mod_rolling``): F_r = −k_r ξ_r − γ_r v_r, ξ_r = ∫v_r dt the rolling
    displacement (R* × relative rotation), limited by μ_r F_ncrit, torque R* × F_r; so the
    torque per radian is k_r R*² and the limit μ_r R* F_ncrit: k_r = k_t and μ_r exact for every
    pair. Twisting (``gran_sub_mod_twisting``, Marshall 2009 eqs. 30, 44): M = −k_tw ψ − γ_tw ω,
    limit μ_tw F_ncrit: k_tw = k_t r_eff² and μ_tw = μ_tor r_eff of the median pair (one number
    per type pair: a named substitute). Dashpots: the seed's 2√(k m*) (§3.2, "all springs
    utilized for friction are damped"), with I* = 2/5 m r² / 2 for the twist."""
    r_eff = d50 / 4.0
    m50 = rho * 4.0 / 3.0 * math.pi * (d50 / 2.0) ** 3
    m_eff, I_eff = m50 / 2.0, 0.4 * m50 * (d50 / 2.0) ** 2 / 2.0
    out = {}
    if "rolling_coefficient" in contact:
        kr = contact["rolling_stiffness"] / r_eff ** 2
        out["rolling"] = {"k": kr, "gamma": 2.0 * math.sqrt(kr * m_eff), "mu": contact["rolling_coefficient"]}
    if "torsion_coefficient" in contact:
        ktw = contact["twisting_stiffness"]
        out["twisting"] = {"k": ktw, "gamma": 2.0 * math.sqrt(ktw * I_eff), "mu": contact["torsion_coefficient"] * r_eff}
    return out


def seed_term_ratios(case, params, xs) -> list:
    """Engine.seed_term_ratios for the median pair (r_eff = x50/4) at the overlaps ``xs`` [m]: ``dmt``
    adhesion 4πγR* with γ = F_adh/(4π⟨r_eff⟩) (the seed's F_adh r_eff/⟨r_eff⟩: exact for every pair),
    the ``rolling sds`` limit μ_r R* F_ncrit with μ_r frozen at the expected overlap ξ_σ (the seed's
    lever √(2 r_eff ξ) grows with the load: a named substitute, as on the other engines), the
    ``twisting sds`` limit μ_tw F_ncrit with μ_tw = μ_tor r_eff of the median pair (exact for it)."""
    c = params.scene.contact
    R = case.scene.psd.median / 2
    r_eff = R / 2
    xs = np.asarray(xs, float)
    rows = []
    if c.adhesion_force:
        rows.append(("adhesion", "dmt 4πγR*, γ = F_adh/(4π⟨r_eff⟩)", [r_eff / c.r_eff_mean] * len(xs)))
    if c.rolling_coefficient is not None:
        rows.append(("rolling limit", "rolling sds μ_r R* F (μ_r frozen at ξ_σ)",
                     list(c.rolling_coefficient * r_eff / np.sqrt(2 * r_eff * xs))))
    if c.torsion_coefficient is not None:
        rows.append(("torsion limit", "twisting sds μ_tw F, μ_tw = μ_tor r_eff (median pair)", [1.0] * len(xs)))
    return rows


def tangential_model(params: dict, base: str = "mindlin") -> str:
    """LAMMPS' tangential model for ``base`` (``mindlin``): ``mindlin/force`` when the case asks for
    the force history (feature ``tangential_history_force``), ``base`` otherwise. LAMMPS keeps the
    force with ``mindlin/force`` and ``mindlin_rescale/force`` only: ``linear_history`` has no such
    form, and a case asking for it on the seed's linear spring is refused."""
    if "tangential_history_force" not in params.get("features", ()):
        return base
    if base != "mindlin":
        raise DerivationError(f"contact.tangential_history: force: LAMMPS' '{base}' tangential model keeps the "
                              "displacement only (its force forms are mindlin/force and mindlin_rescale/force); "
                              "remove contact.tangential_history or run this case on yade")
    return "mindlin/force"


def dashpot(params: dict, xgt: float) -> float:
    """``x_γt`` as given, or 0 when the case drops the tangential dashpot (``contact.tangential_damping:
    false``, params ``tangential_damping``): LAMMPS' tangential damping is x_γt times the normal one."""
    return xgt if params.get("tangential_damping", True) else 0.0


def lammps_numbers(params: dict, case=None) -> dict:
    """The numbers the LAMMPS templates need beyond ``params`` (SI); ``case`` for the scenes with
    rolling and twisting resistance (their median diameter)."""
    mat = params["material"]
    d = restitution_damping(params)
    extra = {}
    contact = params["scene"].get("contact")
    if contact is not None and case is not None and hasattr(getattr(case.scene, "psd", None), "median"):
        extra = rolling_twisting(contact, case.scene.psd.median, mat["rho"])
    return {**extra,
        "tangential": tangential_model(params),   # mindlin, or mindlin/force (contact.tangential_history)
        "damping": d,
        "pair": {"E": mat["E"], "nu": mat["nu"], "kt": 8.0 * params["G_eff_pp"],
                 "xgt": dashpot(params, tangential_damping_factor(params["E_eff_pp"], params["G_eff_pp"]))},
        "wall": {"E": wall_young(params["E_eff_pw"], mat["nu"]), "nu": mat["nu"], "kt": 8.0 * params["G_eff_pw"],
                 "xgt": dashpot(params, tangential_damping_factor(params["E_eff_pw"], params["G_eff_pw"]))},
    }


def seed_law_numbers(E: float, nu: float, rho: float, d50: float, f_adh: float, mu: float,
                     tangential_ratio: float = 2.0 / 7.0) -> dict:
    """``pair_coeff`` numbers for seed 000's law (§3.1-3.2) on ``pair_style granular``, for a
    material (E [Pa], ν, ρ [kg/m³]), median diameter ``d50`` [m], median pull-off ``f_adh`` [N]
    and sliding coefficient μ:

    - ``dmt E η_n0 ν γ``: F = 4/3 E* √R* δ^3/2 − 4πγR* with E* = E/(2(1−ν²)) (the seed's E_eff)
      and γ = F_adh/(4π⟨r_eff⟩), ⟨r_eff⟩ = d50/4: the pull-off F_adh r_eff/⟨r_eff⟩ of every pair,
      exact across the PSD;
    - ``damping viscoelastic`` with η_n0 = γ_n/(m* √R*) of the median pair (:func:`viscoelastic_eta`;
      exact for that pair only: η_n0 m* √R* / γ_n(pair) = √(m* R* / (m*₅₀ R*₅₀)) elsewhere);
    - ``tangential linear_history k_t x_γt μ``: the seed's constant k_t = 2/7 · 4/3 E* x50/2;
      its damping 2√(k_t m*) is matched by x_γt = 2√(k_t m*)/(η_n0 m* √(R* δ)) only at one
      overlap δ (LAMMPS scales tangential damping with the normal one), given here for δ =
      ``d50`` · 1e-3 (returned as ``xgt``; ``xgt_overlap`` says which δ).

    LAMMPS' sliding limit with ``dmt`` is μ|F_ne + 2·4πγR*| = μ(F_Hertz + F_adh) (Thornton 1991,
    Marshall 2009 eq. 43; ``GranSubModNormalDMT::set_fncrit``), the seed's μ|F_n + F_adh| =
    μ|F_Hertz + F_damp|: they differ by μ(F_adh − F_damp), measured in tests/test_lammps_seed_law.py.
    """
    E_eff = E / (2.0 * (1.0 - nu * nu))
    r50 = d50 / 2.0
    m50 = rho * 4.0 / 3.0 * math.pi * r50 ** 3
    m_eff, R_eff = m50 / 2.0, r50 / 2.0
    eta = viscoelastic_eta(seed_gamma_n(E_eff, m_eff), m_eff, R_eff)
    kt = tangential_ratio * 4.0 / 3.0 * E_eff * r50
    overlap = d50 * 1e-3
    xgt = 2.0 * math.sqrt(kt * m_eff) / (eta * m_eff * math.sqrt(R_eff * overlap))
    return {"E": E, "nu": nu, "eta_n0": eta, "surface_energy": f_adh / (4.0 * math.pi * d50 / 4.0),
            "kt": kt, "xgt": xgt, "xgt_overlap": overlap, "mu": mu, "E_eff": E_eff}


def shear_cell_law(params: dict, case, damping: str) -> dict:
    """``pair_coeff`` and wall-fix numbers of the shear cell (seed 000 §3.2-3.3) on
    ``pair_style granular``. ``damping``: the mechanism chosen for ``seed000_damping``
    (``viscoelastic_median_pair`` or ``tsuji_restitution``), or ``restitution`` for a case
    that asks for a restitution coefficient.

    Grain-grain, seed law (``viscoelastic_median_pair``): ``dmt E η_n0 ν γ`` (or ``hertz/material``
    without adhesion) with γ = F_adh/(4π⟨r_eff⟩) (exact per pair), ``damping viscoelastic`` with
    the median pair's η_n0 = γ_n/(m*√R*) (:func:`viscoelastic_eta`), ``tangential linear_history``
    with the seed's k_t = 2/7 · 4/3 E* x50/2 and dashpot 2√(k_t m*) matched at the expected
    overlap ξ_σ of the scene (LAMMPS scales the tangential damping with the normal one), rolling
    and twisting ``sds`` (:func:`rolling_twisting`). Otherwise the verification chain
    (Hertz-Mindlin, ``damping coeff_restitution``) with ``dmt`` when there is adhesion.

    Particle-wall (seed §3.3: the visco-elastic part of eq. 1 only): Hertz with E' = 2(1-ν²)E*_pw
    (:func:`wall_young`), the same damping form (viscoelastic: η_n0 of a median grain against a
    flat wall, m* = m50, R* = x50/2), no adhesion, rolling or twisting; Coulomb μ = ``wall_mu``
    (0 unless ``scene.wall_friction``; with ``wall_friction: shear`` the walls are frictionless
    (``wall``) until the shear stage and frictional (``wall_shear``) from it on)."""
    mat, sc = params["material"], params["scene"]
    c = sc["contact"]
    x50 = case.scene.psd.median
    rho = mat["rho"]
    r50 = x50 / 2.0
    m50 = rho * 4.0 / 3.0 * math.pi * r50 ** 3
    E_pp, E_pw = params["E_eff_pp"], params["E_eff_pw"]
    f_adh = c.get("adhesion_force", 0.0)
    gamma = f_adh / (4.0 * math.pi * c["r_eff_mean"]) if f_adh > 0 else 0.0
    out = {"damping": damping, "surface_energy": gamma, "wall_mu": sc["wall_mu"],
           **rolling_twisting(c, x50, rho)}
    if damping == "viscoelastic_median_pair":
        m_eff, R_eff = m50 / 2.0, r50 / 2.0
        eta = viscoelastic_eta(seed_gamma_n(E_pp, m_eff), m_eff, R_eff)
        kt = c["kt_seed"]
        xi = c["expected_overlap"]
        xgt = 2.0 * math.sqrt(kt * m_eff) / (eta * m_eff * math.sqrt(R_eff * xi))
        out["pair"] = {"E": mat["E"], "nu": mat["nu"], "damp": eta, "tangential": tangential_model(params, "linear_history"),
                       "kt": kt, "xgt": dashpot(params, xgt), "mu": params["friction"], "damping_model": "viscoelastic"}
        eta_w = viscoelastic_eta(seed_gamma_n(E_pw, m50), m50, r50)
        out["wall"] = {"E": wall_young(E_pw, mat["nu"]), "nu": mat["nu"], "damp": eta_w,
                       "damping_model": "viscoelastic"}
    else:
        d = restitution_damping({"restitution": {"target": c["restitution"]["target"]}})
        model = "coeff_restitution" + (" limit_damping" if d["limit_damping"] else "")
        out["pair"] = {"E": mat["E"], "nu": mat["nu"], "damp": d["e_input"], "tangential": tangential_model(params),
                       "kt": 8.0 * params["G_eff_pp"], "xgt": dashpot(params, tangential_damping_factor(E_pp, params["G_eff_pp"])),
                       "mu": params["friction"], "damping_model": model}
        out["wall"] = {"E": wall_young(E_pw, mat["nu"]), "nu": mat["nu"], "damp": d["e_input"],
                       "damping_model": model}
    frictional = {"tangential": tangential_model(params), "kt": 8.0 * params["G_eff_pw"],
                  "xgt": dashpot(params, tangential_damping_factor(E_pw, params["G_eff_pw"])), "mu": out["wall_mu"]}
    frictionless = {"tangential": "linear_nohistory", "kt": None, "xgt": 0.0, "mu": 0.0}
    if out["wall_mu"] > 0 and sc.get("wall_friction_from", 0) > 0:
        # scene.wall_friction: shear: frictionless until the shear stage, the wall fixes redefined there
        out["wall_shear"] = {**out["wall"], **frictional}
    out["wall"].update(frictional if out["wall_mu"] > 0 and not sc.get("wall_friction_from", 0) else frictionless)
    return out


def shear_cell_regions(params: dict, case) -> dict:
    """The shear cell's walls as LAMMPS regions (``units box``), from the same numbers as the STL
    meshes (:func:`orchestrator.scenes.shear_cell.build_meshes`, ``orchestrator.geometry.vaned_piston``):

    - each piston: its plate (a cylinder of the piston radius R_p, ``side out``), the flange face
      that closes the gap pocket (a plane at half the plate thickness behind the face: the flange
      shell spans [-t_p - t_f, -t_p/2] and leaves no room for a grain beside it), and six vanes, each
      the STL's box r ∈ [r_in, x_out], |y| ≤ t/2, z ∈ [-t_p/2, h_v] turned by 60° k (upper: +30°);
    - the sidewall: a cylinder of radius R (``side in``) over the can's height.

    The vanes are the STL's boxes exactly; the plate, flange and sidewall are true circles where
    the STL has ``segments``-gons with their vertices on the circle."""
    s = case.scene
    g = params["scene"]["geometry"]
    tp, vh, t = s.plate_thickness, s.vane_height, s.vane_thickness
    embed = 0.5 * tp
    zu = g["z_upper_face"]
    vane = lambda z0, z1: [g["vane_inner_radius"], g["vane_outer"], -t / 2, t / 2, z0, z1]
    return {
        "R": g["R_cyl"], "R_piston": g["R_piston"], "z_can": g["z_can"],
        "lower": {"floor_z": -tp / 2, "plate_z": [-tp, 0.0], "vane": vane(-embed, vh),
                  "angles": [2 * math.pi * k / 6 for k in range(6)],
                  "names": ["l_floor", "l_plate"] + [f"l_vane{k}" for k in range(6)]},
        "upper": {"ceiling_z": zu + tp / 2, "plate_z": [zu, zu + tp], "vane": vane(zu - vh, zu + embed),
                  "angles": [math.pi / 6 + 2 * math.pi * k / 6 for k in range(6)],
                  "names": ["u_ceil", "u_plate"] + [f"u_vane{k}" for k in range(6)]},
        # the servo's marker atom: outside the sidewall (distance from the axis sqrt(2)(R + d_max/2)),
        # inside the box (the box reaches R + 2 d_max)
        "marker_xy": g["R_cyl"] + 0.5 * s.psd.d_max,
    }


def polygon_area_deficit(segments: int) -> float:
    """1 − A(inscribed regular ``segments``-gon)/A(circle) [-]: the STL's circles against LAMMPS'."""
    return 1.0 - segments / (2 * math.pi) * math.sin(2 * math.pi / segments)


def shear_cell_geometry_difference(case, params: dict, meshes: dict) -> dict:
    """The LAMMPS walls (:func:`shear_cell_regions`) against the STL meshes the other engines get
    (``meshes``: :func:`orchestrator.scenes.shear_cell.build_meshes`, passed in: engines do not
    import scenes), measured on the meshes: ratios STL/LAMMPS
    of the sidewall's enclosed volume, a piston plate's volume, the six vanes' volume, the annulus
    the vanes sweep when turning (π(r_out² − r_in²) h_v, r_out the farthest vane vertex from the axis)
    and the gap pocket's cross-section (sidewall polygon minus plate polygon)."""
    import numpy as np

    from orchestrator.geometry.mesh import Mesh

    s = case.scene
    g = params["scene"]["geometry"]
    reg = shear_cell_regions(params, case)
    lower = meshes["lower"]

    def shell(m, k):
        a, b = m.shells[k]
        return Mesh(m.vertices, m.triangles[a:b], [(0, b - a)])

    plate, vanes = shell(lower, 0), [shell(lower, k) for k in range(2, len(lower.shells))]
    R, Rp, tp, vh = g["R_cyl"], g["R_piston"], s.plate_thickness, s.vane_height
    z0, z1 = g["z_can"]
    vb = reg["lower"]["vane"]
    box_volume = (vb[1] - vb[0]) * (vb[3] - vb[2]) * (vb[5] - vb[4])
    r_out_stl = max(float(np.hypot(*m.vertices[m.triangles.ravel()][:, :2].T).max()) for m in vanes)
    r_out_lmp = math.hypot(vb[1], vb[3])           # the block's outer corner
    swept = lambda r_out: math.pi * (r_out ** 2 - vb[0] ** 2) * vh
    n = g["segments"]
    poly = lambda r: 0.5 * n * r * r * math.sin(2 * math.pi / n)
    return {
        "segments": n,
        "sidewall_volume": meshes["cylinder"].volume() / (math.pi * R * R * (z1 - z0)),
        "plate_volume": plate.volume() / (math.pi * Rp * Rp * tp),
        "vane_volume": sum(m.volume() for m in vanes) / (len(vanes) * box_volume),
        "vane_swept_volume": swept(r_out_stl) / swept(r_out_lmp),
        "pocket_area": (poly(R) - poly(Rp)) / (math.pi * (R * R - Rp * Rp)),
        "sagitta_over_r_min": R * (1 - math.cos(math.pi / n)) / (s.psd.d_min / 2),
    }
