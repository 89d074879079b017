"""Write BENCHMARKS.md: one table of the current figures, generated from benchmarks/results/*.json.

    python benchmarks/summary.py            # rewrite BENCHMARKS.md
    python benchmarks/summary.py --check    # exit 1 if BENCHMARKS.md is not what the JSON gives

Every results file is one run of one benchmark command. A file with a ``figures`` list states its
figures itself (``command``, ``machine``, ``date``, ``history`` and per figure ``id``, ``figure``,
``value``, ``unit``, optional ``target``, ``baseline``, ``note``); files of the commands that
write their own raw numbers (``cli_startup``, ``determinism``, ``shutdown``, ``reliability``,
``plugin_seam``) are read by the extractors below. Where several runs give a figure of the same
``id``, the newest (by ``date``) is the current one. The dated history behind the figures:
docs/benchmarks/.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
OUT = REPO / "BENCHMARKS.md"
COMMAND = "python benchmarks/summary.py"
MAX_LINES = 150

Figure = dict[str, Any]


# ------------------------------------------------------------------------- raw JSON of commands
def _startup(d: dict[str, Any]) -> list[Figure]:
    rows = {(r["code"], r["command"]): r["median_s"] for r in d["rows"]}
    before = next((c for c, _ in rows if c.startswith("--src")), None)
    help_s = rows[("this checkout", "--help (later: cached)")]
    first_s = rows[("this checkout", "--help (first: composed)")]
    error_s = rows[("this checkout", "config error: duration_s=abc")]
    base = f"bare Hydra app: {rows[('bare Hydra app', '--help')]} s"
    old = f"; before the help cache: {rows[(before, '--help (first: composed)')]} s" if before else ""
    return [
        {"id": "cli_help", "figure": "`python -m simlan_data.run --help`, median (later calls: cached)",
         "value": help_s, "unit": "s", "target": "<= 0.5 s", "baseline": base + old,
         "note": f"the first --help after an install or change composes it: {first_s} s",
         "history": "docs/benchmarks/startup.md"},
        {"id": "cli_config_error", "figure": "a config error (`duration_s=abc`), median", "value": error_s,
         "unit": "s", "target": "<= 1 s",
         "baseline": f"before: {rows[(before, 'config error: duration_s=abc')]} s" if before else "",
         "history": "docs/benchmarks/startup.md"},
    ]  # fmt: skip


def _determinism(d: dict[str, Any]) -> list[Figure]:
    same, runs = d["identical_total"]
    return [
        {"id": "determinism", "figure": f"default runs ({d['duration_s']:g} s) byte-identical, half of them side by side",
         "value": same, "unit": f"of {runs}", "target": f"{runs} of {runs}",
         "note": f"code {d['commit']}", "baseline": d.get("baseline", ""), "history": "docs/benchmarks/determinism.md"},
    ]  # fmt: skip


def _shutdown(d: dict[str, Any]) -> list[Figure]:
    ok = sum(1 for t in d["trials"] if t["ok"])
    return [
        {"id": "signal_to_bag", "figure": "SIGTERM/SIGINT to a finalized bag: slowest of "
         f"{len(d['trials'])} ({ok} finalized)", "value": d["bag_s_max"], "unit": "s", "target": "<= 2 s",
         "baseline": d.get("baseline", ""), "history": "docs/benchmarks/hardening.md"},
    ]  # fmt: skip


def _reliability(d: dict[str, Any]) -> list[Figure]:
    kills = d["kills"]
    exact = sum(1 for k in kills if k["prefix_of_reference"])
    overhead = {row["run"]: row["rtf"] for row in d.get("overhead", [])}
    flush = next((v for k, v in overhead.items() if k.startswith("flush every 1 s (")), None)
    off = next((v for k, v in overhead.items() if k.startswith("flushes off")), None)
    out: list[Figure] = [
        {"id": "kill_loss", "figure": f"SIGKILL then recover: most simulated time lost ({exact} of {len(kills)} "
         "exactly the reference's beginning)", "value": round(max(k["loss_at_most_s"] for k in kills), 2),
         "unit": "s", "target": "<= flush period (1 s)", "history": "docs/benchmarks/hardening.md"},
    ]  # fmt: skip
    hard = d.get("hardening")
    if hard:  # issue 21's hostile CLI input and behaviour tests, each with expected and observed
        ok = sum(c["ok"] for c in hard["hostile_inputs"]) + sum(
            t["observed"] == "passed" for t in hard["behaviour_tests"]
        )
        n = len(hard["hostile_inputs"]) + len(hard["behaviour_tests"])
        out.append(
            {"id": "hardening_cases", "figure": f"issue 21's cases as expected: {len(hard['hostile_inputs'])} hostile "
             f"CLI inputs (exit 2, one line, <= 5 s: slowest {max(c['wall_s'] for c in hard['hostile_inputs'])} s) "
             f"and {len(hard['behaviour_tests'])} behaviour tests", "value": ok, "unit": f"of {n}",
             "target": f"{n} of {n}", "baseline": "before issue 21: the 6 inputs hung or were answered wrongly (as the issue lists)",
             "history": "docs/benchmarks/hardening.md"}
        )  # fmt: skip
    if flush is not None and off is not None:
        out.append(
            {"id": "flush_rtf", "figure": "real-time factor with the 1 s flush (default run, 20 s)",
             "value": round(flush, 2), "unit": "x", "baseline": f"flushes off: {off:.2f} x",
             "history": "docs/benchmarks/hardening.md"}
        )  # fmt: skip
    return out


def _plugin_seam(d: dict[str, Any]) -> list[Figure]:
    if d.get("rtf_ratio_new_over_old") is None:
        return []  # a behaviour-only re-run
    med = d["rtf_median"]
    return [
        {"id": "plugin_seam_rtf", "figure": "default scenario real-time factor behind the plug-in seam (ABBA)",
         "value": round(med["new"], 2), "unit": "x", "target": "no slower than before",
         "baseline": f"before the seam ({d['old']}): {med['old']:.2f} x", "history": "docs/benchmarks/plugin-seam.md"},
    ]  # fmt: skip


def _image_encodings(d: dict[str, Any]) -> list[Figure]:
    if d.get("conditions", "").startswith("loaded"):
        return []  # contention figures: kept for the history page, not current
    median = {enc: sorted(r["rtf"] for r in runs)[len(runs) // 2] for enc, runs in d["runs"].items()}
    rate = {enc: runs[0]["mib_per_s"] for enc, runs in d["runs"].items()}
    frame = d["per_frame"]
    return [
        {"id": "depth_16uc1_rate", "figure": "recording rate of the default run, depth as 16UC1 Image (Foxglove shows it)",
         "value": round(rate["16UC1"], 2), "unit": "MiB/s", "baseline": f"compressedDepth PNG: {rate['png']:.2f} MiB/s",
         "note": f"RTF {median['16UC1']:.2f} vs {median['png']:.2f}; per frame "
         f"{frame['depth/16UC1']['total_ms']:.1f} vs {frame['depth/png']['total_ms']:.1f} ms (encode + CDR + zstd)",
         "history": "docs/benchmarks/spine.md"},
    ]  # fmt: skip


EXTRACTORS: dict[str, Callable[[dict[str, Any]], list[Figure]]] = {
    "image_encodings": _image_encodings,
    "cli_startup": _startup,
    "determinism": _determinism,
    "shutdown": _shutdown,
    "reliability": _reliability,
    "plugin_seam": _plugin_seam,
}
# Files without their own command and date (written before the commands recorded them): the
# command as given in the history page, the date from the file name.
KNOWN_COMMANDS = {
    "determinism": "python benchmarks/determinism.py --runs 100 --duration 2",
    "reliability": "python benchmarks/reliability.py --json FILE",
}


# ------------------------------------------------------------------------------------- figures
def _family(path: Path) -> str:
    return re.split(r"_\d{4}-\d\d-\d\d", path.stem, maxsplit=1)[0]


def figures_of(path: Path) -> list[Figure]:
    """The figures of one results file, each with its run's command, machine and date.

    Raises:
        ValueError: a file that neither lists figures nor has an extractor, or lacks a field.
    """
    d = json.loads(path.read_text(encoding="utf-8"))
    family = _family(path)
    if "figures" in d:
        found = d["figures"]
    elif family in EXTRACTORS:
        found = EXTRACTORS[family](d)
    else:
        raise ValueError(f"{path.name}: no 'figures' list and no extractor for '{family}'")
    date_in_name = re.search(r"\d{4}-\d\d-\d\d", path.name)
    run = {
        "command": d.get("command") or KNOWN_COMMANDS.get(family, ""),
        "machine": d.get("machine", ""),
        "date": d.get("date") or (date_in_name.group(0) if date_in_name else ""),
        "history": d.get("history", ""),
        "file": path.name,
    }
    out = []
    for fig in found:
        merged = {**run, **fig}
        missing = [
            k
            for k in ("id", "figure", "value", "command", "machine", "date", "history")
            if merged.get(k) in (None, "")
        ]
        if missing:
            raise ValueError(f"{path.name}: figure {fig.get('id', '?')} lacks {', '.join(missing)}")
        if not merged["command"].startswith(("python ", "benchmarks/")):
            raise ValueError(f"{path.name}: command {merged['command']!r} is not a command line")
        out.append(merged)
    return out


def current(paths: Iterable[Path]) -> list[Figure]:
    """The newest figure of every id, in the order of their first appearance."""
    best: dict[str, Figure] = {}
    order: list[str] = []
    for path in sorted(paths):
        for fig in figures_of(path):
            if fig["id"] not in best:
                order.append(fig["id"])
                best[fig["id"]] = fig
            elif fig["date"] >= best[fig["id"]]["date"]:
                best[fig["id"]] = fig
    pages = {fig["history"]: n for n, fig in reversed(list(enumerate(best[i] for i in order)))}
    return sorted((best[i] for i in order), key=lambda fig: (fig["history"], pages[fig["history"]]))


# ------------------------------------------------------------------------------------ markdown
def _value(fig: Figure) -> str:
    return f"**{fig['value']}** {fig.get('unit', '')}".rstrip()


def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ") if text not in (None, "") else "-"


def render(figs: list[Figure]) -> str:
    """BENCHMARKS.md from the current figures."""
    machines: dict[str, str] = {}
    for fig in figs:
        machines.setdefault(fig["machine"], f"M{len(machines) + 1}")
    history = {fig["history"] for fig in figs}
    lines = [
        "# Benchmarks",
        "",
        f"<!-- generated by `{COMMAND}` from benchmarks/results/*.json: edit the JSON, not this file -->",
        "",
        "The current figure of each benchmark (rows by area): its value, the target where an issue set one, the",
        "baseline measured in the same run, the command that measured it (in `benchmarks/`), the",
        "machine and the date. Timed figures depend on the load of the (shared, 2-core) machines; the",
        "history page of each figure has the load, the re-measurements and the raw numbers. Timed",
        "figures are never asserted by unit tests.",
        "",
        "| figure | value | target | baseline (same run) | command | machine | date | history |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for fig in figs:
        page = fig["history"]
        what = f"{fig['figure']}; {fig['note']}" if fig.get("note") else fig["figure"]
        date = f"[{fig['date'][:16].replace('T', ' ')}](benchmarks/results/{fig['file']})"
        lines.append(
            f"| {_cell(what)} | {_value(fig)} | {_cell(fig.get('target'))} | {_cell(fig.get('baseline'))} "
            f"| `{fig['command']}` | {machines[fig['machine']]} | {date} | [{Path(page).stem}]({page}) |"
        )
    lines += ["", "Machines:", ""]
    lines += [f"- {label}: {machine}" for machine, label in machines.items()]
    lines += [
        "",
        "Notes:",
        "",
        "- Each row comes from one JSON file in `benchmarks/results/` (its date links to it), committed",
        "  with the run. Figures measured before the commands wrote JSON were transcribed from their",
        "  history page into a file that says so (`source`).",
        f"- After a benchmark run, add its JSON to `benchmarks/results/` and run `{COMMAND}`;",
        "  `tests/test_benchmarks_summary.py` fails while this file and the JSON disagree.",
        f"- The dated history ({len(history)} pages, issue by issue): [docs/benchmarks/](docs/benchmarks/index.md).",
    ]
    return "\n".join(lines) + "\n"


def generate(results: Path = RESULTS) -> str:
    return render(current(results.glob("*.json")))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n", 1)[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if BENCHMARKS.md is out of date")
    args = parser.parse_args(argv)
    try:
        text = generate()
    except (ValueError, KeyError, json.JSONDecodeError) as err:
        print(f"error: unusable results file in {RESULTS}: {err}; fix the JSON", file=sys.stderr)
        return 2
    if args.check:
        if OUT.read_text(encoding="utf-8") != text:
            print(f"BENCHMARKS.md is out of date with benchmarks/results/; run {COMMAND}")
            return 1
        return 0
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT.name}: {text.count(chr(10))} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
