"""Run the shell commands of README.md and docs/ as written, and say which ones work.

The docs promise commands; this runs them in a checkout (best: a fresh clone with its own
``.venv``) and writes one JSON line per command: where it is written, the command as run, exit
code, wall time and the tail of its output. Placeholders the docs use (``RUN``, ``OUT``,
``DIR``, ...) are replaced by ``--sub KEY=VALUE``; ``python``/``pip`` become the checkout's
``.venv/bin/python -m ...`` when it has one. A command written twice runs once.

    python scripts/doc_commands.py --list                      # every command with its id
    python scripts/doc_commands.py --run 2 5 7-9 --cwd /tmp/clone --sub RUN=recordings/my_run \\
        --timeout 900 --jsonl /tmp/doc_commands.jsonl

Commands are run with ``bash -c`` in the order given; a command that needs an earlier one's
output (``recordings/my_run``) must come after it. Results go to docs/benchmarks/doc_commands.md
by hand: this script checks, it does not judge what a non-zero exit means (``--inject`` must exit 1).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_BLOCK = re.compile(r"```(?:bash|sh|console|shell)\n(.*?)```", re.S)


def extract(root: Path) -> list[dict]:
    """Every command line of the bash blocks of README.md and docs/**/*.md, continuations joined."""
    files = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    out: list[dict] = []
    seen: set[str] = set()
    for path in files:
        text = path.read_text(encoding="utf-8")
        for m in _BLOCK.finditer(text):
            first = text[: m.start()].count("\n") + 2
            cmd, start = "", 0
            for i, line in enumerate(m.group(1).splitlines()):
                line = line.rstrip()
                if not cmd and (not line.strip() or line.lstrip().startswith("#")):
                    continue
                if not cmd:
                    start = first + i
                cmd = f"{cmd}\n{line}" if cmd else line
                if line.endswith("\\"):
                    continue
                key = _strip_comment(cmd)
                if key not in seen:
                    seen.add(key)
                    out.append({"where": f"{path.relative_to(root)}:{start}", "cmd": key})
                cmd = ""
    for i, item in enumerate(out):
        item["id"] = i
    return out


def _strip_comment(cmd: str) -> str:
    """The command without its trailing ``# comment`` (a '#' outside quotes after whitespace)."""
    lines = []
    for line in cmd.splitlines():
        quote = None
        for j, ch in enumerate(line):
            if ch in "'\"" and quote in (None, ch):
                quote = None if quote else ch
            elif ch == "#" and quote is None and (j == 0 or line[j - 1].isspace()):
                line = line[:j]
                break
        lines.append(line.rstrip())
    return "\n".join(lines).strip()


def prepare(cmd: str, subs: dict[str, str], cwd: Path) -> str:
    """The command with placeholders replaced and python/pip bound to the checkout's venv."""
    for key in sorted(subs, key=len, reverse=True):
        cmd = re.sub(rf"(?<![\w.-]){re.escape(key)}(?![\w-])", subs[key], cmd)
    venv = cwd / ".venv" / "bin"
    if venv.is_dir():
        cmd = re.sub(r"(?<![\w/.-])python(?= )", str(venv / "python"), cmd)
        cmd = re.sub(r"(?<![\w/.-])pip(?= )", f"{venv / 'python'} -m pip", cmd)
        cmd = re.sub(r"(?<![\w/.-])(ray|mkdocs|rerun) ", rf"{venv}/\1 ", cmd)
    return cmd


def table(paths: list[Path]) -> str:
    """One Markdown row per command (a command run twice: its last result), placed where the
    docs hold it now; a command whose text has changed since keeps its old place, marked so."""
    now = {item["cmd"]: item["where"] for item in extract(ROOT)}
    last: dict[str, dict] = {}
    for path in paths:
        for line in path.read_text(encoding="utf-8").splitlines():
            item = json.loads(line)
            last[item["cmd"]] = item
    for cmd, item in last.items():
        item["where"] = now.get(cmd, f"{item['where']} (since changed)")
    rows = ["| where | command (as written) | exit | wall s |", "| --- | --- | --- | --- |"]
    order = sorted(
        last.values(), key=lambda i: (i["where"].split(":")[0], int(i["where"].split(":")[1].split()[0]))
    )
    for item in order:
        cmd = " ".join(item["cmd"].replace("\\\n", " ").split()).replace("|", "\\|")
        rows.append(f"| {item['where']} | `{cmd}` | {item['rc']} | {item['wall_s']:g} |")
    return "\n".join(rows)


def _ids(specs: list[str], n: int) -> list[int]:
    ids: list[int] = []
    for spec in specs:
        lo, _, hi = spec.partition("-")
        ids.extend(range(int(lo), int(hi or lo) + 1))
    bad = [i for i in ids if not 0 <= i < n]
    if bad:
        raise SystemExit(f"--run: ids {bad} out of range 0-{n - 1}; see --list")
    return ids


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--list", action="store_true", help="print every command with its id")
    ap.add_argument("--run", nargs="*", default=[], metavar="ID", help="ids or ranges (3-7) to run")
    ap.add_argument("--cwd", type=Path, default=ROOT, help="the checkout to run in")
    ap.add_argument("--sub", action="append", default=[], metavar="KEY=VALUE", help="placeholder value")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per command")
    ap.add_argument("--jsonl", type=Path, help="append one result line per command here")
    ap.add_argument(
        "--table", nargs="*", type=Path, metavar="JSONL", help="print results as a Markdown table"
    )
    args = ap.parse_args()
    if args.table:
        print(table(args.table))
        return 0
    commands = extract(args.cwd)
    if args.list:
        for item in commands:
            print(f"{item['id']:3d} {item['where']:32s} {item['cmd']}")
        return 0
    subs = dict(s.split("=", 1) for s in args.sub)
    for i in _ids(args.run, len(commands)):
        item = dict(commands[i])
        item["ran"] = prepare(item["cmd"], subs, args.cwd)
        t0 = time.monotonic()
        try:
            proc = subprocess.run(
                ["bash", "-c", item["ran"]],
                cwd=args.cwd,
                capture_output=True,
                text=True,
                timeout=args.timeout,
                check=False,
            )
            item["rc"], tail = proc.returncode, (proc.stdout + proc.stderr)[-1500:]
        except subprocess.TimeoutExpired as exc:
            item["rc"], tail = "timeout", str(exc.stdout or "")[-1500:]
        item["wall_s"] = round(time.monotonic() - t0, 1)
        item["tail"] = tail
        print(f"[{i}] rc={item['rc']} {item['wall_s']} s  {item['cmd'][:100]}", flush=True)
        if args.jsonl:
            with args.jsonl.open("a", encoding="utf-8") as f:
                f.write(json.dumps(item) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
