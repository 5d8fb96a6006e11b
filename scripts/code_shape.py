#!/usr/bin/env python3
"""Prints the shape of the code in src/: file sizes, function lengths, and the
length of each stage's `systems` (issue 41's figures).

    python3 scripts/code_shape.py            # the working tree
    python3 scripts/code_shape.py --rev REV  # a commit (read with git show)

A function's length counts the lines from its `fn` line to the line of its
closing brace at the same indentation (unit tests excluded: code after
`#[cfg(test)]\\nmod tests`). A stage's `systems` length is that of its
`fn systems` in `src/stages/<kind>/mod.rs`, including the closures it builds.
"""

import argparse
import re
import statistics
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def sources(rev):
    if rev is None:
        for p in sorted((ROOT / "src").rglob("*.rs")):
            yield str(p.relative_to(ROOT)), p.read_text()
        return
    names = subprocess.run(
        ["git", "ls-tree", "-r", "--name-only", rev, "src"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout.split()
    for n in sorted(names):
        if n.endswith(".rs"):
            text = subprocess.run(
                ["git", "show", f"{rev}:{n}"], cwd=ROOT, capture_output=True, text=True, check=True
            ).stdout
            yield n, text


FN = re.compile(r"^(\s*)(?:pub(?:\([a-z]+\))?\s+)?(?:const\s+)?(?:unsafe\s+)?fn\s+(\w+)")


def functions(text):
    """(name, first line, length) of every fn before the unit tests."""
    code = text.split("#[cfg(test)]\nmod tests")[0].split("\n")
    out = []
    for i, line in enumerate(code):
        m = FN.match(line)
        if not m or line.rstrip().endswith(";"):
            continue
        indent = m.group(1)
        for j in range(i, len(code)):
            if code[j] == indent + "}" or (j == i and line.rstrip().endswith("}")):
                out.append((m.group(2), i + 1, j - i + 1))
                break
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rev", default=None)
    ap.add_argument("--over", type=int, default=150)
    args = ap.parse_args()
    files = list(sources(args.rev))
    total = sum(t.count("\n") for _, t in files)
    big = sorted(((t.count("\n"), n) for n, t in files), reverse=True)
    print(f"src: {len(files)} files, {total} lines")
    print("files over 1000 lines:", ", ".join(f"{n} ({c})" for c, n in big if c > 1000) or "none")
    long = []
    systems = {}
    for name, text in files:
        for fname, line, length in functions(text):
            if length > args.over:
                long.append((length, f"{name}:{line} {fname}"))
            m = re.match(r"src/stages/(\w+)/mod\.rs", name)
            if m and fname == "systems":
                systems[m.group(1)] = length
    long.sort(reverse=True)
    print(f"functions over {args.over} lines: {len(long)}")
    for length, where in long:
        print(f"  {length:5d}  {where}")
    if systems:
        lens = sorted(systems.values())
        print(
            f"stage systems: {len(lens)}, median {statistics.median(lens):.0f} lines, "
            f"max {max(lens)}, over 60: {sum(l > 60 for l in lens)}"
        )
        for kind, length in sorted(systems.items(), key=lambda kv: -kv[1]):
            print(f"  {length:5d}  {kind}")


if __name__ == "__main__":
    main()
