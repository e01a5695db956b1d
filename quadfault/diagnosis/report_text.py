"""The text of ``report.md`` (figures in :mod:`quadfault.diagnosis.report`)."""

from __future__ import annotations

from quadfault.diagnosis.residuals import channel_unit
from quadfault.diagnosis.result import DiagnosisResult


def _one(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_one(x) for x in v) + "]"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _fmt(d: dict) -> str:
    return "; ".join(f"{k} = {_one(v)}" for k, v in d.items())


def _folds(d: dict) -> str:
    return "; ".join(f"{k}: " + ", ".join(_one(x) for x in v) for k, v in d.items())


def _effect_rows(effects, reason=False) -> list:
    head = "| effect | parameters | 1-sigma | bounds | held-out improvement (alone) | per fold |"
    head += " reason |" if reason else " explanation |"
    L = [head, "|" + "---|" * (7)]
    for e in effects:
        last = e.reason if reason else e.explanation
        L.append(
            f"| {e.name} | {_fmt(e.params)} | {_fmt(e.uncertainty)} | {_fmt(e.bounds)} | "
            f"{100 * e.improvement:.1f}% | {_folds(e.folds)} | {last} |"
        )
    return L


def markdown(res: DiagnosisResult, source: str) -> str:
    lo, hi = (res.model_ci95 or (float("nan"), float("nan")))[:2]
    L = [
        f"# Model-mismatch diagnosis of `{source}`",
        "",
        f"Summary: {res.summary()}.",
        "",
        f"**Verdict: {res.verdict}.** Held-out residual RMS reduced by "
        f"{100 * res.model_improvement:.1f}% (95% interval {100 * lo:.1f} to {100 * hi:.1f}%) "
        f"with the accepted effects ({res.seconds:.1f} s).",
        "",
    ]
    sc = res.scoring or {}
    if sc.get("excluded"):
        L += [
            f"Not scored ({100 * sc.get('excluded_fraction', 0.0):.1f}% of the recording; "
            f"{sc.get('scored_blocks')} of {sc.get('blocks')} blocks scored):",
            "",
        ]
        L += [f"- {e['t0']:.2f}-{e['t1']:.2f} s: {e['reason']}" for e in sc["excluded"]]
        L.append("")
    if sc.get("note"):
        L += [f"Scoring: {sc['note']}.", ""]
    L += ["## Effects", ""]
    L += (
        _effect_rows(res.effects)
        if res.effects
        else [
            "None accepted: no candidate improved held-out residuals by a meaningful margin with "
            "physically plausible parameters."
        ]
    )
    if res.indistinguishable:
        L += ["", "## Indistinguishable in this log", ""]
        for n in res.indistinguishable:
            L.append(f"- **{n.get('summary') or ' or '.join(n['names'])}**: {n['reason']}.")
            if n.get("separate_by"):
                L.append(f"  What would separate them: {n['separate_by']}.")
    if res.estimator:
        est = res.estimator
        if est.get("eta"):
            L += [
                "",
                f"Online estimator beside the weak-rotor hypothesis ({est['estimator']}, "
                f"the same recording, median over {est['from_s']:.1f}-{est['to_s']:.1f} s): "
                f"eta = {_one([round(v, 3) for v in est['eta']])}; weakest rotor "
                f"{est['weakest_rotor']}, the diagnosis names rotor "
                f"{est['diagnosis_weakest_rotor']} "
                f"({'agree' if est['agrees'] else 'they disagree'}).",
            ]
        else:
            L += ["", f"Online estimator: not run ({est.get('error', '')})."]
    if res.suspect:
        L += ["", "## Suspect (a parameter at its bound: not identified)", ""]
        L += _effect_rows(res.suspect, reason=True)
    if res.rejected:
        L += ["", "## Rejected candidates", ""]
        L += _effect_rows(res.rejected, reason=True)
    L += [
        "",
        "## Residual per channel (held out)",
        "",
        "| channel | nominal RMS | diagnosed RMS | improvement | 95% interval | noise scale | "
        "weight |",
        "|---|---|---|---|---|---|---|",
    ]
    for ch, noise, w in zip(res.channels, res.scale, res.weights or [1.0] * len(res.channels)):
        c = res.channel_scores.get(ch, {})
        ci = c.get("ci95", [float("nan")] * 2)
        L.append(
            f"| {ch} [{channel_unit(ch)}] | {c.get('rmse_before', float('nan')):.4g} | "
            f"{c.get('rmse_after', float('nan')):.4g} | "
            f"{100 * c.get('improvement', 0.0):.1f}% | {100 * ci[0]:.1f} to "
            f"{100 * ci[1]:.1f}% | {noise:.3g} | {w:.2f} |"
        )
    L += ["", "![residuals](residuals.png)", "", "## Where", ""]
    if res.where:
        L += ["| channel | t0 [s] | t1 [s] | note |", "|---|---|---|---|"]
        L += [f"| {w.channel} | {w.t0:.2f} | {w.t1:.2f} | {w.note} |" for w in res.where]
    else:
        L.append("No interval where the nominal model exceeds 4x the smoothed noise.")
    L += ["", "## Regimes", ""]
    for r in res.regimes:
        bins = ", ".join(f"[{a:.3g}, {b:.3g}]: {c:.3g}" for a, b, c in r["bins_lo_hi_rms"])
        others = ", ".join(
            f"{k} {v:.2f}" for k, v in sorted(r["all"].items(), key=lambda kv: -kv[1])
        )
        L.append(
            f"- **{r['channel']}** follows **{r['variable']}** [{r['unit']}] "
            f"(|corr| {r['correlation']:.2f}; all: {others}). Residual RMS per bin: {bins}."
        )
    if not res.regimes:
        L.append("No channel disagrees beyond 1.5x its noise scale.")
    L += ["", "![regimes](regimes.png)", "", "## Open-loop prediction (held out)", ""]
    p = res.prediction
    if p:
        L.append(
            f"From {p['n_starts']} recorded states; each start predicted by the fit that "
            "did not see its fold. RMS error at each horizon:"
        )
        L.append("")
        hs = " | ".join(f"{h:.2f} s" for h in p["horizons_s"])
        L += [f"| quantity | predictor | {hs} |", "|---|---|" + "---|" * len(p["horizons_s"])]
        for key in (
            "position_rmse_m",
            "velocity_rmse_m_per_s",
            "attitude_rmse_deg",
            "rate_rmse_rad_per_s",
        ):
            for label, errs in p.get(key, {}).items():
                L.append(f"| {key} | {label} | " + " | ".join(f"{e:.4g}" for e in errs) + " |")
    else:
        L.append("Not available: no free-flight stretch long enough.")
    L += ["", "![prediction](prediction.png)", ""]
    if res.not_identifiable:
        L += [
            "## Not identifiable from this log",
            "",
            "Left out before any fit: the log lacks the evidence these effects need.",
            "",
        ]
        L += [f"- **{n['name']}**: {n['reason']}" for n in res.not_identifiable]
        L.append("")
    if res.assumptions:
        a = res.assumptions
        L += ["## Assumed constants", "", f"Note: {a['note']}.", ""]
        if a.get("depends"):
            L += [
                f"- {n} depends on the assumed {' and '.join(v)}" for n, v in a["depends"].items()
            ]
        if a.get("independent"):
            L.append("- independent of them: " + ", ".join(a["independent"]))
        L.append("")
    return "\n".join(L)
