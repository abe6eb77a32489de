#!/usr/bin/env python3
"""Checks that every relative link and image in README.md and docs/*.md points at a file the
repository tracks, and that every #anchor names a heading of its target (GitHub's slug rules).

    scripts/check-doc-links.py [--allow PATH ...]    exit 1 when a link is broken

--allow names targets that may be missing (files another change adds)."""
import argparse
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
LINK = re.compile(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")  # the "](target)" of every link and image


def tracked():
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    files = {pathlib.PurePosixPath(p) for p in out.splitlines()}
    dirs = {d for f in files for d in f.parents}
    return files, dirs


def slug(heading):
    s = heading.strip().lower()
    s = re.sub(r"[^\w\- ]", "", s)  # keep letters, digits, underscore, hyphen, space
    return s.replace(" ", "-")


def anchors(path):
    seen, result = {}, set()
    in_code = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
            continue
        m = None if in_code else re.match(r"#{1,6}\s+(.*)", line)
        if m:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            result.add(base if n == 0 else f"{base}-{n}")
    return result


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--allow", action="append", default=[])
    args = parser.parse_args()
    files, dirs = tracked()
    allowed = {pathlib.PurePosixPath(a) for a in args.allow}
    docs = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
    broken, checked, allowed_missing = [], 0, []
    for doc in docs:
        text = doc.read_text(encoding="utf-8")
        text = re.sub(r"```.*?```", "", text, flags=re.S)  # links inside code blocks are not links
        for target in LINK.findall(text):
            if re.match(r"[a-z]+:", target):
                continue
            checked += 1
            path, _, anchor = target.partition("#")
            rel = pathlib.PurePosixPath(doc.relative_to(ROOT).parent.as_posix())
            resolved = rel if not path else pathlib.PurePosixPath(
                pathlib.PurePath("/", rel, path).as_posix()).relative_to("/")
            parts = []
            for p in resolved.parts:  # normalise a/../b
                if p == "..":
                    parts.pop() if parts else None
                elif p != ".":
                    parts.append(p)
            resolved = pathlib.PurePosixPath(*parts) if parts else pathlib.PurePosixPath(".")
            where = f"{doc.relative_to(ROOT)}: {target}"
            if resolved in allowed:
                allowed_missing.append(where)
                continue
            if resolved not in files and resolved not in dirs and str(resolved) != ".":
                broken.append(f"{where} (no such file)")
                continue
            if anchor and resolved.suffix == ".md" and anchor not in anchors(ROOT / resolved):
                broken.append(f"{where} (no heading '#{anchor}')")
    for a in allowed_missing:
        print(f"allowed: {a}")
    for b in broken:
        print(f"broken: {b}")
    print(f"{checked} links in {len(docs)} files, {len(broken)} broken, {len(allowed_missing)} allowed")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
