"""Grain-by-grain comparison of two aligned frame sets (needs grain identity, see
:func:`orchestrator.compare.align.match_identity`).

For every aligned state k and every identified grain i:

* trajectory error e_i(k) = |x_i^B(k) − x_i^A(k)| [m] (B in A's coordinate frame), also in d50 of A;
* displacements from the first aligned state, u_i^A(k) = x_i^A(k) − x_i^A(0) and likewise u_i^B(k);
  they *agree* when |u^B − u^A| ≤ ``atol`` + ``rtol`` |u^A| (defaults: atol = 0.1 d50,
  rtol = 0.2; a grain that barely moves must match to a tenth of a diameter, a grain that moved
  far to 20 % of its displacement).

Tables: ``grains`` (state, control value, id_a, id_b, error, error_d50, u_a, u_b, du, agree) and
``states`` (per state: n, median / p90 / max / RMS error [m] and in d50, median |u_a|, fraction
agreeing). Grains absent (NaN) in either set at a state are left out of that state.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from ..analysis.plots import _fig

__all__ = ["GrainComparison", "grain_errors"]


@dataclass
class GrainComparison:
    tables: dict = field(default_factory=dict)
    scalars: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    labels: tuple = ("A", "B")

    def plot(self):
        s = self.tables["states"]
        x = s["control_value"].to_numpy()
        ctl = self.options.get("control", "control")
        if ctl == "angle":
            x, ctl = np.degrees(x), "angle [deg]"
        fig, (a1, a2) = _fig(ncols=2, w=4.6)
        a1.plot(x, s.median_error_d50, "o-", label="median")
        a1.plot(x, s.p90_error_d50, "s--", label="90th percentile")
        a1.plot(x, s.max_error_d50, "^:", label="max")
        a1.set_xlabel(ctl)
        a1.set_ylabel("|x_B − x_A| / d50")
        a1.set_title(f"per-grain trajectory error ({self.labels[1]} vs {self.labels[0]})", fontsize=9)
        a1.legend(fontsize=7)
        a2.plot(x, s.fraction_agree, "o-")
        a2.set_ylim(-0.02, 1.02)
        a2.set_xlabel(ctl)
        a2.set_ylabel("fraction of grains")
        a2.set_title(f"displacement agrees (atol {self.options['atol_d50']:g} d50, rtol {self.options['rtol']:g})",
                     fontsize=9)
        return fig


def grain_errors(alignment, frames_a=None, frames_b=None, atol_d50: float = 0.1, rtol: float = 0.2) -> GrainComparison:
    """Per-grain trajectory error and displacement agreement over the aligned states."""
    ident = alignment.identity
    if ident is None or ident.n == 0:
        raise ValueError("grain-level comparison needs grain identity (align(..., identity=True) found no grains)")
    fa = frames_a if frames_a is not None else alignment.a.frames
    fb = frames_b if frames_b is not None else alignment.b.frames
    st = alignment.states
    ra, rb = ident.rows_a, ident.rows_b
    r = fa.radius[ra]
    d50 = 2 * float(np.nanmedian(fa.radius[np.isfinite(fa.radius)]))
    atol = atol_d50 * d50
    PA, PB = fa.position, fb.position
    transform = alignment.transform if frames_b is None else None
    def tb(p):
        return alignment.transform_b(p) if transform is not None else p
    xa0 = PA[int(st.frame_a.iloc[0])][ra]
    xb0 = tb(PB[int(st.frame_b.iloc[0])][rb])
    rows, srows = [], []
    for s in range(len(st)):
        xa = PA[int(st.frame_a.iloc[s])][ra]
        xb = tb(PB[int(st.frame_b.iloc[s])][rb])
        ok = np.isfinite(xa).all(1) & np.isfinite(xb).all(1) & np.isfinite(xa0).all(1) & np.isfinite(xb0).all(1)
        e = np.linalg.norm(xb - xa, axis=1)
        ua, ub = xa - xa0, xb - xb0
        na, nb = np.linalg.norm(ua, axis=1), np.linalg.norm(ub, axis=1)
        du = np.linalg.norm(ub - ua, axis=1)
        agree = du <= atol + rtol * na
        v = float(st.value.iloc[s])
        rows.append(pd.DataFrame({"state": s, "control_value": v, "id_a": fa.ids[ra][ok], "id_b": fb.ids[rb][ok],
                                  "radius_a": r[ok], "error": e[ok], "error_d50": e[ok] / d50, "u_a": na[ok],
                                  "u_b": nb[ok], "du": du[ok], "agree": agree[ok]}))
        eo = e[ok]
        srows.append({"state": s, "control_value": v, "frame_a": int(st.frame_a.iloc[s]),
                      "frame_b": int(st.frame_b.iloc[s]), "n": int(ok.sum()),
                      "median_error": float(np.median(eo)) if len(eo) else np.nan,
                      "p90_error": float(np.percentile(eo, 90)) if len(eo) else np.nan,
                      "max_error": float(eo.max()) if len(eo) else np.nan,
                      "rms_error": float(np.sqrt(np.mean(eo ** 2))) if len(eo) else np.nan,
                      "median_u_a": float(np.median(na[ok])) if len(eo) else np.nan,
                      "fraction_agree": float(agree[ok].mean()) if len(eo) else np.nan})
    S = pd.DataFrame(srows)
    for c in ("median_error", "p90_error", "max_error", "rms_error", "median_u_a"):
        S[c + "_d50"] = S[c] / d50
    scal = {"d50_m": d50, "grains_identified": int(ident.n), "identity": ident.method,
            "max_median_error_d50": float(np.nanmax(S.median_error_d50)),
            "max_p90_error_d50": float(np.nanmax(S.p90_error_d50)),
            "final_fraction_agree": float(S.fraction_agree.iloc[-1]),
            "min_fraction_agree": float(np.nanmin(S.fraction_agree))}
    return GrainComparison({"grains": pd.concat(rows, ignore_index=True), "states": S}, scal,
                           {"atol_d50": atol_d50, "rtol": rtol, "control": alignment.control},
                           (alignment.a.label, alignment.b.label))
