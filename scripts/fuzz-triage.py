#!/usr/bin/env python3
"""Replays the inputs a fuzz target failed on and sorts them by whose code failed.

    scripts/fuzz-triage.py FUZZ_BINARY ARTIFACT...

Each artifact (crash-*, leak-*, timeout-*, oom-* written by libFuzzer) is run once more through
the target; the first sanitizer or libFuzzer report of that run belongs to Rime when the first stack frame that is neither the sanitizer/fuzzer runtime,
the C/C++ runtime nor a header under /usr/include is in this repository; it belongs to a library
(libhdf5, libassimp, ...) when that frame is in the library's shared object. Prints one line per
artifact and exits 1 when any is Rime's (a finding to fix), 0 otherwise (also for inputs that fail
only after others, "no-repro", which are listed).
"""
import os
import re
import subprocess
import sys

REPO = os.path.realpath(os.path.join(os.path.dirname(__file__), ".."))
RUNTIME_LIBS = ("libc.so", "libstdc++.so", "libgcc_s.so", "libm.so", "ld-linux")
REPORT_START = re.compile(r"^==\d+==ERROR: |^\S+:\d+:\d+: runtime error: |^==\d+== ERROR: libFuzzer: ")
FRAME = re.compile(r"^\s*#\d+ 0x[0-9a-f]+ (?:in )?(.*)$")
REPLAY_FLAGS = ["-timeout=10", "-rss_limit_mb=2048", "-malloc_limit_mb=1024"]  # as scripts/fuzz.sh runs it


def frame_owner(text):
    """'rime', a library's file name, or None to look at the caller."""
    library = re.search(r"\((/[^ )+]+)\+0x[0-9a-f]+\)", text)
    if library:
        name = os.path.basename(library.group(1))
        if ".so" not in name:
            return None  # interceptor or fuzzer runtime linked into the target
        return None if name.startswith(RUNTIME_LIBS) else name
    source = re.search(r" (/\S+?):\d+", text)
    if source:
        path = os.path.realpath(source.group(1))
        return "rime" if path.startswith(REPO + os.sep) else None
    return None


def owner(report):
    first = report[0]
    ub = re.match(r"^(\S+):\d+:\d+: runtime error: ", first)
    if ub and os.path.realpath(ub.group(1)).startswith(REPO + os.sep):
        return "rime"
    owners = []
    for line in report:
        m = FRAME.match(line)
        if m and line.lstrip().startswith("#0 "):
            owners.append(None)  # a new stack (leak reports hold several)
        if m and owners and owners[-1] is None:
            owners[-1] = frame_owner(m.group(1))
    if "rime" in owners:
        return "rime"
    found = [o for o in owners if o]
    return found[0] if found else "rime"  # no stack: count it as ours to be safe


def main():
    binary, artifacts = sys.argv[1], sys.argv[2:]
    ours = 0
    for artifact in artifacts:
        try:
            run = subprocess.run([binary, *REPLAY_FLAGS, artifact], capture_output=True, text=True, errors="replace", timeout=300)
            lines, rc = (run.stdout + run.stderr).splitlines(), run.returncode
        except subprocess.TimeoutExpired:
            lines, rc = ["replay took over 300 s"], 1
        start = next((k for k, l in enumerate(lines) if REPORT_START.match(l)), None)
        if rc == 0:
            # Failed only after earlier inputs (state kept inside a library between runs, e.g. HDF5's caches).
            who, summary = "no-repro", "does not fail when run alone"
        elif start is None:
            who, summary = "rime", lines[-1] if lines else "no output"
        else:
            report = lines[start:]
            who = owner(report)
            summary = next((l for l in report if l.startswith("SUMMARY:")), report[0])
        ours += who == "rime"
        summary = re.sub(r"0x[0-9a-f]+|\(BuildId: [0-9a-f]+\)|==\d+==", "", summary)
        print(f"{'RIME' if who == 'rime' else who}\t{os.path.basename(artifact)}\t{summary.strip()[:150]}")
    return 1 if ours else 0


if __name__ == "__main__":
    sys.exit(main())
