"""What `orthosim bench` prints: one line per figure of a bench record, beside its target.

The record (`run_bench`'s JSON) is the result; these lines are its reading for a person at a
terminal. The command (`orthosim.cli.bench`) only echoes them.
"""

from __future__ import annotations


def summary_lines(record: dict, out_file) -> list[str]:
    """The lines `orthosim bench` prints for `record`, written to `out_file`."""
    lines = []
    if record.get("closure"):
        lines.append(f"closure: {record['closure']['closure_over_rest_of_step']:.2f} of the rest of the step (target <= 1)")
    rb = record.get("render_backends")
    if rb:
        lines.append("render fps per backend: " + ", ".join(f"{k} {v['fps']:.1f}" for k, v in rb["fps"].items())
                     + "".join(f"; {k} {v:.2f}" for k, v in rb.get("ratios", {}).items()))
    fps = record["fps"]
    shown = ", ".join(f"{k} {v:.1f}" if v is not None else f"{k} pending" for k, v in fps.items())
    lines.append(f"fps (median, target {record['target_fps']}): {shown} -> {out_file}")
    for part in (_startup, _trees, _label_pass, _staging, _report, _batch, _memory, _failures):
        lines += part(record)
    return lines


def _startup(record: dict) -> list[str]:
    st = record.get("startup")
    if not st:
        return []
    return [f"start-up: first step {st['startup_s']:.2f} s after launching `orthosim run` (target {st['target_s']:.1f} s; "
            f"bare python {st['python_start_s']:.2f} s, load {st['load_avg_1min']:.1f})"]


def _trees(record: dict) -> list[str]:
    trees = record.get("spheretree_build")
    if not trees:
        return []
    return [f"sphere trees of {trees['teeth']} teeth built in {trees['build_s']:.1f} s on {trees['workers']} cores "
            f"(target {trees['target_s']:.0f} s; one process {trees['build_s_one_process']:.1f} s), "
            f"loaded in {1000 * trees['load_s']:.0f} ms"]


def _label_pass(record: dict) -> list[str]:
    lp = record.get("label_pass")
    if not lp:
        return []
    return [f"label pass: at most {100 * lp['worst_ratio']:.0f} % of a golden's render time "
            f"(target {100 * lp['target_ratio']:.0f} %; draw alone {100 * lp['worst_ratio_draw_alone']:.0f} %)"]


def _staging(record: dict) -> list[str]:
    staged = record.get("staging")
    if not staged:
        return []
    big = staged["setup_28_teeth"]
    v = staged["verify_28_teeth"]
    return [f"staging: {big['teeth']} teeth, {big['stages']} stages planned in {big['staging_s']:.1f} s "
            f"(target {big['target_s']:.0f} s); " + ", ".join(f"{k} {v['staging_s']:.1f} s" for k, v in staged["cases"].items()),
            f"stage verify: {v['stages']} stages of {v['teeth']} teeth checked in {v['verify_s']:.1f} s "
            f"(target {v['target_s']:.0f} s; x{v['verify_to_planning']:.2f} its planning time)"]


def _report(record: dict) -> list[str]:
    r = record.get("report")
    if not r:
        return []
    return [f"report of {r['cases']} cases x 3 detectors from existing runs: {r['report_s']:.1f} s "
            f"(target {r['target_s']:.0f} s), PDF {r['pdf_s']:.1f} s"]


def _figure(value: float | None, spec: str) -> str:
    """`value` formatted, or "null (failed)" for a figure whose sub-run failed (orthosim_bench.subruns):
    a missing figure, or a ratio whose baseline did not run, never reads as a number or as met."""
    return "null (failed)" if value is None else format(value, spec)


def _batch(record: dict) -> list[str]:
    b = record.get("batch")
    if not b:
        return []
    return [f"batch: {_figure(b.get('per_minute_1_worker'), '.2f')} animations/min with 1 worker, "
            f"{_figure(b.get('per_minute_2_workers'), '.2f')} with 2 (x{_figure(b['ratio_2_to_1'], '.2f')}, "
            f"target x{b['target_ratio_2_to_1']})"]


def _memory(record: dict) -> list[str]:
    m = record.get("memory")
    if not m:
        return []
    return [f"peak private memory: {_figure(m['run_10k_steps_no_render_mb'], '.0f')} MB for {m['run_no_render']['steps']} "
            f"steps of {m['run_no_render'].get('step_days', '?')} days without rendering, "
            f"{_figure(m['render_2000_frames_mb'], '.0f')} MB for {m['render']['frames']} frames (target {m['target_mb']:.0f} MB)"]


def _failures(record: dict) -> list[str]:
    failed = record.get("failures") or []
    if not failed:
        return []
    return [f"{len(failed)} sub-run(s) failed or were refused; their figures are null: "
            + ", ".join(f["figure"] for f in failed)]
