"""`orthosim occlusion`: occlusal measures and the contacts of each facing pair of a case's model at rest."""

from __future__ import annotations

from pathlib import Path

import click

from orthosim.cli.options import gl_option, parse_size, select_gl


@click.command()
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: out/<case name>-occlusion).")
@click.option("--size", default="800x600", show_default=True, callback=parse_size, help="Image size WIDTHxHEIGHT.")
@click.option("--no-render", is_flag=True, help="Write occlusion.json only.")
@gl_option
def occlusion(case: Path, out_dir: Path | None, size, no_render: bool, gl: str | None) -> None:
    """Occlusal measures and contacts per pair of a case's model at rest; contact areas drawn (Figure 7)."""
    if not no_render:
        select_gl(gl)
    from orthosim.storage.atomic import write_json
    from orthosim.exchange.case import load_case
    from orthosim.analysis.occlusalcontacts import occlusal_contacts, occlusion_record

    dent = load_case(case).build_dentition()
    out_dir = out_dir or Path("out") / f"{case.stem}-occlusion"
    contacts = occlusal_contacts(dent)
    record = occlusion_record(dent, contacts)
    write_json(out_dir / "occlusion.json", record)
    if not no_render:
        from orthosim_render.occlusion_figure import write_occlusal_contacts

        write_occlusal_contacts(dent, contacts, out_dir, size)
    click.echo(f"{len(record['contacts'])} facing pairs in contact; overjet {record.get('overjet_mm', float('nan')):.2f} mm, "
               f"overbite {record.get('overbite_mm', float('nan')):.2f} mm -> {out_dir}")
