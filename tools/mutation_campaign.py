#!/usr/bin/env python3
"""Mutation campaign: feeds mutated inputs through every reader and command of `hullcut` and
classifies what happens.

Each case copies a valid input (the shipped dataset datasets/cut-small, the example scenarios),
mutates one file (a number replaced by a hostile value, bytes flipped, inserted or removed, lines
dropped or repeated, the file cut short, structural attacks: a YAML alias bomb, a 100k-character
value, PLY counts, PNG sizes), runs the commands that read that file, and sorts the outcome:

  ok        exit 0 and no NaN/inf in the output or the report
  refused   exit 1 or 2 with a message (and whether it names the file)
  nan       exit 0 but NaN or inf in the output or the report ("accepted but wrong")
  panic     a Rust panic (exit 101 or "panicked at")
  abort     killed by a signal (failed allocation under the memory limit, stack overflow)
  hang      still running at the time limit

Each run gets a memory limit (RLIMIT_AS) so that an allocation sized by a hostile number aborts
instead of swapping the machine, and a time limit. Usage:

    python3 tools/mutation_campaign.py --bin target/debug/hullcut --cases 400 --seed 1 \\
        --out docs/bench/robustness

writes runs.csv (every run: file, mutation, command, outcome, the start of the message) and
summary.md. Exit status 1 when any case panicked, aborted, hung or accepted NaN.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATASET = ROOT / "datasets" / "cut-small"
SCENARIOS = ROOT / "examples" / "scenarios"

HOSTILE_NUMBERS = [
    "0", "-0", "-1", "1e-300", "1e-30", "1e300", "1e308", "-1e308", "1e19", "nan", "NaN", "inf", "-inf",
    "9223372036854775807", "-9223372036854775808", "18446744073709551615", "1000000000", "4294967296",
    "0.5", "2", "3.5", "-3",
]
NUMBER = re.compile(rb"(?<![A-Za-z_])-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def mutate_text(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One mutation of a text file; returns the new bytes and a description."""
    kind = rng.choice(["number", "number", "number", "bytes", "line_drop", "line_dup", "truncate", "long", "alias"])
    numbers = list(NUMBER.finditer(data))
    if kind == "number" and numbers:
        m = rng.choice(numbers)
        value = rng.choice(HOSTILE_NUMBERS)
        return data[: m.start()] + value.encode() + data[m.end():], f"number at byte {m.start()} -> {value}"
    if kind == "line_drop" or kind == "line_dup":
        lines = data.split(b"\n")
        i = rng.randrange(len(lines))
        if kind == "line_drop":
            del lines[i]
        else:
            lines.insert(i, lines[i])
        return b"\n".join(lines), f"{kind} line {i + 1}"
    if kind == "truncate":
        n = rng.randrange(len(data) + 1)
        return data[:n], f"truncated to {n} bytes"
    if kind == "long":
        i = rng.randrange(len(data) + 1)
        return data[:i] + b"x" * 100_000 + data[i:], f"100k characters at byte {i}"
    if kind == "alias":
        bomb = b"a: &a [x, x, x, x, x, x, x, x, x, x]\n" + b"".join(
            b"%c: &%c [*%c, *%c, *%c, *%c, *%c, *%c, *%c, *%c, *%c, *%c]\n" % ((98 + k, 98 + k) + (97 + k,) * 10)
            for k in range(9)
        )
        return data + b"\n" + bomb, "YAML alias bomb appended"
    return flip_bytes(data, rng)


def flip_bytes(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    out = bytearray(data)
    edits = []
    for _ in range(rng.randint(1, 4)):
        if not out:
            break
        i = rng.randrange(len(out))
        op = rng.randrange(3)
        if op == 0:
            out[i] = rng.randrange(256)
        elif op == 1:
            out.insert(i, rng.randrange(256))
        else:
            del out[i]
        edits.append(f"{['set', 'insert', 'delete'][op]}@{i}")
    return bytes(out), "bytes " + ",".join(edits)


def mutate_png(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    kind = rng.choice(["bytes", "truncate", "size", "size"])
    if kind == "size" and data[:8] == b"\x89PNG\r\n\x1a\n":
        w = rng.choice([0, 1, 65535, 100000, 2**31 - 1, 2**32 - 1])
        h = rng.choice([0, 1, 65535, 100000, 2**31 - 1])
        ihdr = bytearray(data[8:33])
        ihdr[8:12] = w.to_bytes(4, "big")
        ihdr[12:16] = h.to_bytes(4, "big")
        crc = zlib.crc32(bytes(ihdr[4:21])).to_bytes(4, "big")
        ihdr[21:25] = crc
        return data[:8] + bytes(ihdr) + data[33:], f"IHDR size {w}x{h} (valid CRC)"
    if kind == "truncate":
        n = rng.randrange(len(data))
        return data[:n], f"truncated to {n} bytes"
    return flip_bytes(data, rng)


def mutate_ply(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    kind = rng.choice(["count", "count", "vertex", "bytes", "truncate", "empty_element"])
    end = data.find(b"end_header\n")
    if kind == "count":
        value = rng.choice(["0", "1", "18446744073709551615", "9223372036854775807", "1000000000", "-1"])
        element = rng.choice([b"vertex", b"face"])
        new = re.sub(rb"element " + element + rb" \d+", b"element " + element + b" " + value.encode(), data, count=1)
        return new, f"element {element.decode()} count -> {value}"
    if kind == "empty_element" and end > 0:
        return data[:end] + b"element nothing 9223372036854775808\n" + data[end:], "element without properties, 2^63 rows"
    if kind == "vertex" and end > 0:
        body = end + len(b"end_header\n")
        value = rng.choice([1e300, float("nan"), float("inf"), -1e308, 1e19])
        import struct

        if b"binary_little_endian" in data[:end] and body + 8 <= len(data):
            off = body + 8 * rng.randrange(min(12, (len(data) - body) // 8))
            return data[:off] + struct.pack("<d", value) + data[off + 8:], f"vertex coordinate -> {value}"
    if kind == "truncate":
        n = rng.randrange(len(data))
        return data[:n], f"truncated to {n} bytes"
    return flip_bytes(data, rng)


def mutate_jpeg(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    kind = rng.choice(["bytes", "truncate", "size"])
    sof = data.find(b"\xff\xc0")
    if kind == "size" and sof > 0 and sof + 9 <= len(data):
        h = rng.choice([0, 1, 65535])
        w = rng.choice([0, 1, 65535])
        out = bytearray(data)
        out[sof + 5: sof + 7] = h.to_bytes(2, "big")
        out[sof + 7: sof + 9] = w.to_bytes(2, "big")
        return bytes(out), f"SOF0 size {w}x{h}"
    if kind == "truncate":
        n = rng.randrange(len(data))
        return data[:n], f"truncated to {n} bytes"
    return flip_bytes(data, rng)


class Runner:
    def __init__(self, binary: Path, timeout: float, memory_gib: float):
        self.binary = binary
        self.timeout = timeout
        self.memory = int(memory_gib * (1 << 30))

    def run(self, args: list[str], cwd: Path) -> dict:
        def limits():
            resource.setrlimit(resource.RLIMIT_AS, (self.memory, self.memory))
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
            os.setsid()

        start = time.monotonic()
        proc = subprocess.Popen(
            [str(self.binary), *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=limits
        )
        try:
            out, err = proc.communicate(timeout=self.timeout)
            rc = proc.returncode
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            rc = None
        return {
            "rc": rc,
            "seconds": round(time.monotonic() - start, 2),
            "stdout": out.decode("utf-8", "replace"),
            "stderr": err.decode("utf-8", "replace"),
        }


NAN = re.compile(r"(?<![A-Za-z])(NaN|nan|-?inf)(?![A-Za-z])")


def classify(result: dict, report: Path | None, file_name: str) -> tuple[str, str]:
    err = result["stderr"]
    if result["rc"] is None:
        return "hang", f"no exit within the time limit"
    if "panicked at" in err or result["rc"] == 101:
        line = next((l for l in err.splitlines() if "panicked" in l), "")
        return "panic", line[:300]
    if result["rc"] < 0:
        return "abort", f"signal {-result['rc']}: " + (err.strip().splitlines() or [""])[-1][:300]
    if result["rc"] == 0:
        text = result["stdout"] + err
        if report is not None and report.exists():
            text += report.read_text(errors="replace")
        m = NAN.search(text)
        if m:
            return "nan", text[max(0, m.start() - 80): m.end() + 40].replace("\n", " ")
        return "ok", ""
    message = err.strip()
    first = message.splitlines()[-1] if message else ""
    named = "named" if file_name in message else "unnamed"
    return f"refused ({named})", first[:300]


def cases_for(dataset: Path, scenarios: list[Path], colmap: Path) -> list[tuple[Path, str]]:
    """(file to mutate, kind) pairs: every reader's inputs."""
    targets = [
        (colmap / "cameras.txt", "text"),
        (colmap / "images.txt", "text"),
        (dataset / "rig.yaml", "text"),
        (dataset / "dataset.toml", "text"),
        (dataset / "frames.csv", "text"),
        (dataset / "tool.json", "text"),
        (dataset / "tool.ply", "ply"),
        (dataset / "truth" / "poses.jsonl", "text"),
        (dataset / "cam0" / "000001.png", "png"),
        (dataset / "masks" / "cam2" / "000001.png", "png"),
    ]
    targets += [(s, "text") for s in scenarios]
    return [(p, k) for p, k in targets if p.exists()]


def commands(target: Path, work: Path, dataset: Path) -> list[tuple[str, list[str], Path | None]]:
    """The commands that read `target`, as (name, args, report file)."""
    report = work / "report.json"
    out = work / "out"
    if target.suffix == ".toml" and target.parent.name == "scenarios":
        return [("sim", ["sim", "--scenario", str(target), "--report", str(report)], report)]
    if target.parent.name == "colmap":
        return [("import colmap", ["import-calibration", "--colmap", str(target.parent), "--out", str(work / "r.yaml")],
                 None)]
    if target.name == "rig.yaml":
        cmds = [("rig show", ["rig", "show", str(target)], None)]
    else:
        cmds = []
    cmds.append(
        (
            "reconstruct",
            ["reconstruct", "--dataset", str(dataset), "--out", str(out), "--frames", "0:3", "--voxel", "0.004",
             "--report", str(report)],
            report,
        )
    )
    if target.parent.parent.name == "dataset" and target.suffix == ".png" or target.name == "rig.yaml":
        cmds.append(
            ("segment", ["segment", "--dataset", str(dataset), "--frames", "0:3", "--out", str(work / "seg"),
                         "--report", str(report)], report)
        )
    cmds.append(
        (
            "run",
            ["run", "--dataset", str(dataset), "--frames", "0:3", "--cell", "0.01", "--rrd", str(work / "run.rrd"),
             "--report", str(report)],
            report,
        )
    )
    return cmds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", type=Path, default=ROOT / "target" / "debug" / "hullcut")
    ap.add_argument("--cases", type=int, default=300, help="mutated inputs (each runs 1-3 commands)")
    ap.add_argument("--calib-cases", type=int, default=0,
                    help="mutated chessboard photos through `calibrate` (OpenCV's stereo samples; slower)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds before a run counts as a hang")
    ap.add_argument("--memory-gib", type=float, default=8.0, help="address-space limit per run")
    ap.add_argument("--out", type=Path, default=None, help="folder for runs.csv and summary.md")
    args = ap.parse_args()

    rng = random.Random(args.seed)
    runner = Runner(args.bin.resolve(), args.timeout, args.memory_gib)
    records = []
    with tempfile.TemporaryDirectory(prefix="hullcut-campaign-") as tmp:
        tmp = Path(tmp)
        colmap_model = tmp / "colmap-model"
        subprocess.run([str(runner.binary), "rig", "export", str(DATASET / "rig.yaml"), "--colmap", str(colmap_model)],
                       check=True, stdout=subprocess.DEVNULL)
        for case in range(args.cases):
            work = tmp / f"case{case}"
            dataset = work / "dataset"
            shutil.copytree(DATASET, dataset)
            scen_dir = work / "scenarios"
            shutil.copytree(SCENARIOS, scen_dir)
            colmap = work / "colmap"
            shutil.copytree(colmap_model, colmap)
            targets = cases_for(dataset, sorted(scen_dir.glob("*.toml")), colmap)
            target, kind = rng.choice(targets)
            data = target.read_bytes()
            new, how = {"text": mutate_text, "png": mutate_png, "ply": mutate_ply}[kind](data, rng)
            target.write_bytes(new)
            rel = target.relative_to(work)
            for name, cmd, report in commands(target, work, dataset):
                if report is not None and report.exists():
                    report.unlink()
                result = runner.run(cmd, work)
                outcome, detail = classify(result, report, target.name)
                records.append(
                    {"case": case, "file": str(rel), "mutation": how, "command": name, "outcome": outcome,
                     "rc": result["rc"], "seconds": result["seconds"], "detail": detail}
                )
                print(f"{case:4} {str(rel):32} {name:12} {outcome:18} {how[:50]}", flush=True)
            shutil.rmtree(work, ignore_errors=True)
        for case in range(args.calib_cases):
            work = tmp / f"calib{case}"
            tree = work / "images"
            subprocess.run(["bash", str(ROOT / "tools" / "stereo-sample.sh"), str(tree)], check=True,
                           stdout=subprocess.DEVNULL)
            photos = sorted(tree.glob("*/*.jpg"))
            target = rng.choice(photos)
            new, how = mutate_jpeg(target.read_bytes(), rng)
            target.write_bytes(new)
            rel = target.relative_to(work)
            report = work / "calib.json"
            cmd = ["calibrate", "--images", str(tree), "--pattern", "9x6", "--square", "0.025", "--out",
                   str(work / "rig.yaml"), "--report", str(report)]
            result = runner.run(cmd, work)
            outcome, detail = classify(result, report, target.name)
            records.append(
                {"case": args.cases + case, "file": str(rel), "mutation": how, "command": "calibrate",
                 "outcome": outcome, "rc": result["rc"], "seconds": result["seconds"], "detail": detail}
            )
            print(f"{case:4} {str(rel):32} calibrate    {outcome:18} {how[:50]}", flush=True)
            shutil.rmtree(work, ignore_errors=True)

    tally: dict[str, int] = {}
    for r in records:
        tally[r["outcome"]] = tally.get(r["outcome"], 0) + 1
    bad = [r for r in records if r["outcome"] in ("panic", "abort", "hang", "nan")]
    print(json.dumps(tally, indent=1))
    by_command: dict[str, dict[str, int]] = {}
    for r in records:
        row = by_command.setdefault(r["command"], {})
        row[r["outcome"]] = row.get(r["outcome"], 0) + 1
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        with open(args.out / "runs.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["case", "file", "mutation", "command", "outcome", "rc", "seconds", "message"])
            for r in records:
                w.writerow([r["case"], r["file"], r["mutation"], r["command"], r["outcome"], r["rc"], r["seconds"],
                            r["detail"][:100]])
        lines = [
            "# Mutation campaign",
            "",
            f"`python3 tools/mutation_campaign.py --cases {args.cases} --calib-cases {args.calib_cases} "
            f"--seed {args.seed} --timeout {args.timeout:g} --out {args.out}`",
            "",
            f"{args.cases + args.calib_cases} mutated inputs, {len(records)} runs.",
            "",
            "| outcome | runs |",
            "|---|---|",
            *[f"| {k} | {v} |" for k, v in sorted(tally.items())],
            "",
            "| command | " + " | ".join(sorted(tally)) + " |",
            "|---|" + "---|" * len(tally),
            *[f"| {c} | " + " | ".join(str(row.get(k, 0)) for k in sorted(tally)) + " |" for c, row in sorted(by_command.items())],
            "",
        ]
        if bad:
            lines += ["## Failures", "", "| file | mutation | command | outcome | detail |", "|---|---|---|---|---|"]
            lines += [
                f"| {r['file']} | {r['mutation']} | {r['command']} | {r['outcome']} | {r['detail'].replace('|', '/')} |"
                for r in bad
            ]
        (args.out / "summary.md").write_text("\n".join(lines) + "\n")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
