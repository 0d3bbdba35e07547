"""`orthosim evidence`: the clinical evidence table run on the model (`orthosim.evidence`), written as
evidence.json and a page (`orthosim_render.evidence_page`)."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("evidence")
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=Path),
              help="Folder for evidence.json and index.html (new, or one an earlier evidence run wrote).")
@click.option("--parameters", type=click.Choice(["clinical", "paper"]), default="clinical", show_default=True,
              help="Rate-law parameter set to test.")
@click.option("--no-real", is_flag=True, help="Skip the rows on the real patient's teeth (../shared/data).")
def evidence(out_dir: Path, parameters: str, no_real: bool) -> None:
    """Run the clinical evidence table on the model; write evidence.json and index.html."""
    from orthosim_render.evidence_page import outcome_lines, write_evidence

    from orthosim.evidence import load_evidence, run_rows
    from orthosim.evidence.run import evidence_models
    from orthosim.mechanics.ratelaw import DAYS_PER_MONTH, PARAMETER_SETS
    from orthosim.runtime.outputfolder import output_folder

    law = PARAMETER_SETS[parameters]
    rows = load_evidence()
    with output_folder(out_dir) as staging:
        results = run_rows(evidence_models(law, not no_real), rows)
        text = (f"threshold {law.threshold_cN:g} cN, saturation {law.saturation_cN:g} cN, "
                f"{law.max_rate_mm_per_day * DAYS_PER_MONTH:.3g} mm/month, mandibular bone factor {law.mandibular_bone_factor:g}")
        write_evidence(results, staging, parameters, text)
    for line in outcome_lines(results, parameters, out_dir / "index.html"):
        click.echo(line)
