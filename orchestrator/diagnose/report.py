"""Writing a diagnosis: ``diagnosis.json``, ``machine.toml``, ``report.md``, ``holdout.json`` and plots."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..atomic import atomic_write_bytes, atomic_write_json, atomic_write_text
from ..machine import machine_to_toml

if TYPE_CHECKING:
    from .core import CaseResult, Diagnosis


def report_markdown(d: "Diagnosis") -> str:
    """Human-readable report (Markdown)."""
    j = d.to_json()
    lines = [f"# Diagnosis of `{d.case_name}`", ""]
    al = j["alignment"]
    lines += ["## Alignment (recording artefacts, not physics)", "",
              f"- logger time offset: {al['time_offset_s']} s",
              *([f"- spindle angle of tooth 0 at the first force sample: {al['spindle_angle_deg']} deg"]
                if "spindle_angle_deg" in al else []), "",
              "| channel | scale | offset | noise floor |", "| --- | --- | --- | --- |"]
    for ch, v in al["channels"].items():
        key = ch.replace("_mm", "_fe_um") if ch.endswith("_mm") and not ch.endswith("_ref_mm") else ch
        lines.append(f"| {ch} | {v['scale']} | {v['offset']} | {d.noise.get(key, '')} |")
    lines += ["", "Channel scales are not estimated: a position scale error is indistinguishable from a lead error "
              "(`pitch_error`), a current scale error from a mass or friction mismatch; those are physics here.", ""]
    lines += ["## Effects", ""]
    if not j["effects"]:
        lines += ["None: nothing but noise separates the recording from the twin.", ""]
    for e in j["effects"]:
        where = f"axis {e['axis']}" if "axis" in e else "cutting process"
        lines += [f"### {e['effect']} ({where}), confidence {e['confidence']}", "",
                  "| parameter | value | 90 % interval |", "| --- | --- | --- |"]
        for k, v in e["parameters"].items():
            ci = e["ci90"].get(k, [v, v])
            lines.append(f"| {k} | {v} | {ci[0]} .. {ci[1]} |")
        w = e["where"]
        lines += ["", f"- channels: {', '.join(e['channels'])}",
                  f"- where: {len(w['time_s'])} window(s) {w['time_s'][:3]}{' ...' if len(w['time_s']) > 3 else ''}, "
                  f"lines {w['lines']}, event {w['event']}, frequency {w['frequency_Hz']} Hz",
                  f"- evidence: {e['evidence']}", ""]
    if d.notes:
        lines += ["## Not diagnosed", "", *[f"- {n}" for n in d.notes], ""]
    lines += ["## Unexplained", ""]
    if not j["unexplained"]:
        lines += ["Nothing above the noise floor is left.", ""]
    for u in j["unexplained"]:
        lines.append(f"- {', '.join(u['channels'])}: rms {u['rms']} in {u['where']['time_s'][:3]}, "
                     f"lines {u['where'].get('lines')}, event {u['where'].get('event')}, "
                     f"frequency {u['where'].get('frequency_Hz')} Hz")
    lines += ["", "## RMS before / after", "", "| case | channel | before | after |", "| --- | --- | --- | --- |"]
    for ch, v in j["rms_before"].items():
        lines.append(f"| {d.case_name} | {ch} | {v} | {j['rms_after'][ch]} |")
    if d.holdout:
        name = Path(d.holdout["case"]).name
        for ch, v in d.holdout["rms_before"].items():
            lines.append(f"| {name} (held out) | {ch} | {v} | {d.holdout['rms_after'][ch]} |")
    lines += ["", "## Model", "", f"{j['model']}; changed keys:", ""]
    lines += [f"- `{k}`" for k in sorted(d.provenance)] or ["- none"]
    lines += ["", "## Selection and refit log", "", "```", *d.log, "```", ""]
    return "\n".join(lines)


def _png(fig) -> bytes:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()


def residual_map_png(result: "CaseResult", axis: str, path: Path, effects: list[dict]) -> Path:
    """Residual maps of one axis: why each effect was chosen.

    Panels: following-error residual against commanded velocity (up- vs
    down-stroke gap: gravity, feed-forward, backlash), current residual
    against velocity (sign-dependent: friction; same sign: gravity), both
    against position (periodic: ripple, pitch), and the residual in time with
    the effects' windows shaded.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    prep, sim, c = result.prep, result.sim, result.cols[axis]
    t = prep.t
    v = np.gradient(prep.commands[axis], t) * 1e3  # mm/s
    x = prep.commands[axis] * 1e3
    fe_r = prep.fe[axis] - sim.fe[axis][:, 0]
    rows = c.rows_fe
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    ax[0, 0].scatter(v[rows], fe_r[rows], s=2, c=np.sign(v[rows]), cmap="coolwarm")
    ax[0, 0].set(xlabel="commanded velocity [mm/s]", ylabel="FE residual, baseline [µm]",
                 title="following-error gap: up- vs down-strokes")
    if c.rows_tc.size:
        tc_r = prep.current[axis] - sim.current[axis][:, 0]
        rt = c.rows_tc
        ax[0, 1].scatter(v[rt], tc_r[rt], s=2, c=np.sign(v[rt]), cmap="coolwarm")
        ax[0, 1].set(xlabel="commanded velocity [mm/s]", ylabel="current residual, baseline [A]",
                     title="torque residual vs velocity sign")
        moving = rt[np.abs(v[rt]) > 0.5]
        ax[1, 0].scatter(x[moving], tc_r[moving], s=2, c="tab:green")
        ax[1, 0].set(xlabel=f"{axis} command [mm]", ylabel="current residual [A]",
                     title="current residual vs position (moving)")
    else:
        ax[0, 1].text(0.5, 0.5, "no current channel", ha="center")
        ax[1, 0].scatter(x[rows], fe_r[rows], s=2)
        ax[1, 0].set(xlabel=f"{axis} command [mm]", ylabel="FE residual [µm]")
    after = prep.fe[axis] - sim.fe[axis][:, 1]
    ax[1, 1].plot(t[rows], fe_r[rows], lw=0.6, label="before")
    ax[1, 1].plot(t[rows], after[rows], lw=0.6, label="after")
    for e in effects:
        if e.get("axis") != axis:
            continue
        for w0, w1 in e["where"]["time_s"]:
            ax[1, 1].axvspan(w0, w1, alpha=0.12, color="tab:red")
    ax[1, 1].set(xlabel="t [s] (logger clock)", ylabel="FE residual [µm]", title="residual in time (effects shaded)")
    ax[1, 1].legend(fontsize=8)
    fig.suptitle(f"{result.name}: residual maps, axis {axis}")
    fig.tight_layout()
    data = _png(fig)
    plt.close(fig)
    return atomic_write_bytes(path, data)


def traces_png(result: "CaseResult", axis: str, path: Path) -> Path:
    """Measured, before (baseline twin) and after (diagnosed model) traces of one axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    prep, sim, c = result.prep, result.sim, result.cols[axis]
    t = prep.t
    n = 2 if c.rows_tc.size else 1
    fig, ax = plt.subplots(n, 1, figsize=(11, 3.2 * n), squeeze=False)
    rows = c.rows_fe
    ax[0, 0].plot(t[rows], prep.fe[axis][rows], lw=0.8, color="k", label="measured")
    ax[0, 0].plot(t[rows], sim.fe[axis][rows, 0], lw=0.8, label="before")
    ax[0, 0].plot(t[rows], sim.fe[axis][rows, 1], lw=0.8, ls="--", label="after")
    ax[0, 0].set(ylabel=f"{axis} following error [µm]")
    ax[0, 0].legend(fontsize=8)
    if n == 2:
        rt = c.rows_tc
        ax[1, 0].plot(t[rt], prep.current[axis][rt], lw=0.8, color="k", label="measured")
        ax[1, 0].plot(t[rt], sim.current[axis][rt, 0], lw=0.8, label="before")
        ax[1, 0].plot(t[rt], sim.current[axis][rt, 1], lw=0.8, ls="--", label="after")
        ax[1, 0].set(ylabel=f"{axis} current command [A]")
    ax[-1, 0].set(xlabel="t [s] (logger clock)")
    fig.suptitle(f"{result.name}: measured / before / after, axis {axis}")
    fig.tight_layout()
    data = _png(fig)
    plt.close(fig)
    return atomic_write_bytes(path, data)


def cutting_map_png(d: "Diagnosis", path: Path) -> Path:
    """Cutting residual maps: why each cutting effect was chosen.

    Panels: the force residual against the spindle angle of tooth 0 (mean per
    5 degree bin, before and after: runout repeats once per revolution, a
    helix or edge force once per tooth), the force spectra of the longest cut
    (measured, twin before and after: chatter is a peak off the spindle
    harmonics), the residual in time with the cutting effects' windows shaded,
    and the spindle-speed residual against the cutting torque (droop).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .cutting_locate import _spectrum
    from .cutting_merge import spindle_angle_of

    cres = d.cutting
    data, cols, sim = cres.data, cres.cols, cres.sim
    rows = cols.rows
    angle = np.degrees(spindle_angle_of(cres))[rows]
    inside = data.cuts.mask(data.t.size)[rows]
    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    bins = np.arange(0.0, 365.0, 5.0)
    centre = 0.5 * (bins[1:] + bins[:-1])
    k = np.clip(np.digitize(angle, bins) - 1, 0, centre.size - 1)
    for j, (label, ls) in enumerate((("before", "-"), ("after", "--"))):
        for c, name, color in ((0, "fx", "tab:blue"), (1, "fy", "tab:orange")):
            model = sim.fx[rows, j] if c == 0 else sim.fy[rows, j]
            r = data.measured[rows, c] - model
            mean = np.array([r[(k == i) & inside].mean() if np.any((k == i) & inside) else np.nan
                             for i in range(centre.size)])
            ax[0, 0].plot(centre, mean, ls=ls, color=color, label=f"{name} {label}")
    ax[0, 0].axhline(0.0, color="k", lw=0.5)
    ax[0, 0].set(xlabel="spindle angle of tooth 0 [deg]", ylabel="mean force residual [N]",
                 title="force residual vs spindle angle (cuts)")
    ax[0, 0].legend(fontsize=7, ncol=2)
    i0, i1 = max(data.cuts.bounds, key=lambda b: b[1] - b[0])
    tt = data.t[i0:i1]
    for y, label, lw in ((data.measured[i0:i1, 0], "measured", 0.9), (sim.fx[i0:i1, 0], "twin before", 0.7),
                         (sim.fx[i0:i1, 1], "twin after", 0.7)):
        f, p, _ = _spectrum(tt, y)
        ax[0, 1].semilogy(f, np.maximum(p, 1e-12), lw=lw, label=label)
    for e in d.effects:
        if e["effect"] == "chatter":
            ax[0, 1].axvline(e["parameters"]["frequency_Hz"], color="tab:red", ls=":", label="chatter")
    ax[0, 1].set(xlabel="frequency [Hz]", ylabel="fx power", title="force spectrum, longest cut")
    ax[0, 1].legend(fontsize=7)
    t = data.t[rows]
    ax[1, 0].plot(t, data.measured[rows, 1] - sim.fy[rows, 0], lw=0.4, label="fy before")
    ax[1, 0].plot(t, data.measured[rows, 1] - sim.fy[rows, 1], lw=0.4, label="fy after")
    for e in d.effects:
        if "axis" in e:
            continue
        for w0, w1 in e["where"]["time_s"]:
            ax[1, 0].axvspan(w0, w1, alpha=0.1, color="tab:red")
    ax[1, 0].set(xlabel="t [s] (logger clock)", ylabel="force residual [N]",
                 title="residual in time (cutting effects shaded)")
    ax[1, 0].legend(fontsize=7)
    if cres.droop_rows is not None:
        _, tq, res = cres.droop_rows
        ax[1, 1].scatter(tq, res, s=2)
        k_d = cres.model.get("spindle_droop", {}).get("rpm_per_Nm")
        if k_d:
            xs = np.linspace(0.0, float(np.max(tq)), 10)
            ax[1, 1].plot(xs, -k_d * xs, color="tab:red", label=f"-{k_d:.1f} rpm/N.m")
            ax[1, 1].legend(fontsize=7)
        ax[1, 1].set(xlabel="cutting torque [N.m]", ylabel="spindle_rpm - command [rpm]",
                     title="spindle speed vs torque (droop)")
    else:
        ax[1, 1].text(0.5, 0.5, "no spindle_rpm", ha="center")
    fig.suptitle(f"{d.case_name}: cutting residual maps")
    fig.tight_layout()
    data_png = _png(fig)
    plt.close(fig)
    return atomic_write_bytes(path, data_png)


def write_outputs(d: "Diagnosis", out: Path, plots: bool = True) -> dict[str, Path]:
    """Write every output file of a diagnosis into ``out`` (atomically)."""
    files = {
        "diagnosis": atomic_write_json(out / "diagnosis.json", d.to_json()),
        "machine": atomic_write_text(out / "machine.toml", machine_to_toml(d.machine, d.provenance)),
        "report": atomic_write_text(out / "report.md", report_markdown(d)),
    }
    if d.holdout:
        files["holdout"] = atomic_write_json(out / "holdout.json", d.holdout)
    if plots and d.cutting is not None:
        files["cutting_map"] = cutting_map_png(d, out / "cutting_map.png")
    if plots:
        for k, result in enumerate(d.results):
            tag = "" if k == 0 else "_holdout"
            for a in result.cols:
                if k == 0:
                    files[f"residual_map_{a}"] = residual_map_png(result, a, out / f"residual_map_{a}.png", d.effects)
                files[f"traces_{a}{tag}"] = traces_png(result, a, out / f"traces_{a}{tag}.png")
    return files
