#!/usr/bin/env python3
"""Hashes the outputs of every shipped config, to show a restructuring changed no byte.

Runs every numbered config in configs/, every configs/surface/*.toml, and every
configs/plane/*.toml on each photo in data/textures/, each into its own folder
under a scratch directory, each from an empty analysis cache of its own (so a
subset hashes as the whole does), and prints one line per output file: `run file sha256`. metrics.json is hashed without the figures that
measure the machine rather than the result (seconds, rates, peak memory, the
memory limit, the thread count, cache hits).

    cargo build --release
    python3 scripts/output_hashes.py > before.txt      # on the old commit
    python3 scripts/output_hashes.py > after.txt       # on the new commit
    diff before.txt after.txt                          # nothing: byte-identical

Options: --bin PATH (default target/release/surfsynth), --only SUBSTRING (runs
whose name contains it), --threads N (default 2; results do not depend on it).
"""

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# Keys of metrics.json that measure the machine or the run's timing, or say
# whether an analysis came from the cache (the jump-map analysis reports its
# statistics only when it runs).
MACHINE_KEYS = {
    "peak_rss_bytes",
    "limit_bytes",
    "limit_source",
    "threads",
    "config",
    "cache_hit",
    "refine_analysis_cached",
    "explained_variance",
    "pca_components",
    "full_fraction",
    "mean_jumps",
}


def machine_key(key):
    return (
        key in MACHINE_KEYS
        or key == "seconds"
        or key.endswith("_seconds")
        or key.endswith("_per_second")
    )


def strip(value):
    if isinstance(value, dict):
        return {k: strip(v) for k, v in value.items() if not machine_key(k)}
    if isinstance(value, list):
        return [strip(v) for v in value]
    return value


def file_hash(path):
    if path.name == "metrics.json":
        data = strip(json.loads(path.read_text()))
        blob = json.dumps(data, sort_keys=True).encode()
    else:
        blob = path.read_bytes()
    return hashlib.sha256(blob).hexdigest()


def runs():
    configs = ROOT / "configs"
    for cfg in sorted(configs.glob("[0-9]*.toml")):
        yield cfg.stem, cfg, []
    for cfg in sorted((configs / "surface").glob("*.toml")):
        yield f"surface_{cfg.stem}", cfg, []
    photos = sorted((ROOT / "data" / "textures").glob("*.png"))
    for cfg in sorted((configs / "plane").glob("*.toml")):
        for photo in photos:
            yield (
                f"plane_{cfg.stem}_{photo.stem}",
                cfg,
                ["--set", f"input.exemplar={photo}"],
            )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bin", default=str(ROOT / "target" / "release" / "surfsynth"))
    parser.add_argument("--only", default="")
    parser.add_argument("--threads", default="2")
    args = parser.parse_args()

    scratch = Path(tempfile.mkdtemp(prefix="surfsynth_hashes_"))
    failed = 0
    try:
        for name, cfg, extra in runs():
            if args.only not in name:
                continue
            out = scratch / name
            cache = scratch / "cache"
            shutil.rmtree(cache, ignore_errors=True)
            env = dict(os.environ, SURFSYNTH_CACHE=str(cache))
            cmd = [args.bin, "run", str(cfg), "--out", str(out), "-q", "--threads", args.threads]
            result = subprocess.run(cmd + extra, cwd=ROOT, env=env, capture_output=True, text=True)
            if result.returncode != 0:
                failed += 1
                print(f"{name} EXIT {result.returncode}", flush=True)
                print(result.stderr.strip(), file=sys.stderr)
                continue
            for path in sorted(out.iterdir()):
                print(f"{name} {path.name} {file_hash(path)}", flush=True)
            shutil.rmtree(out)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
