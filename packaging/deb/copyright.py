#!/usr/bin/env python3
"""Writes the package's DEP-5 copyright file (usr/share/doc/qt-therapy/copyright).

The hand-written part (copyright.in: the header, the workspace, the study's model, the Rust
standard library) comes first; then one paragraph per crate that the programs link, found in
`cargo metadata` from the programs' crates along normal dependencies (build scripts and
procedural macros run only while building: neither they nor what only they use are linked);
then one stand-alone License paragraph per license named, from licenses/. A license with no
text there, or a license expression this script cannot put in DEP-5's words, stops the build.

  copyright.py --metadata META.json --crates a,b,c --maintainer "Name <addr>" --rustc "rustc 1.95.0"
"""

import argparse
import json
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

# Files whose lines may say who holds a crate's copyright.
LICENSE_FILE = re.compile(r"^(LICEN[CS]E|COPYING|COPYRIGHT|UNLICENSE|NOTICE)", re.I)
# "Copyright (c) 2015 Name", "Copyright © ...", "// Copyright 2015-2016 Name." but not the
# Apache license's template ("Copyright [yyyy] [name of copyright owner]") nor prose.
COPYRIGHT_LINE = re.compile(r"^\W*(Copyright\s*(?:\(c\)|©|\d{4}).*)$", re.I)
# ... nor a license text's own notice (the GPL's "Copyright (C) 1989, 1991 Free Software
# Foundation" in a bundled COPYING).
TEMPLATE = re.compile(
    r"\[yyyy\]|\{yyyy\}|<year>|\[name of copyright owner\]|<copyright holders>|Free Software Foundation",
    re.I,
)
# Where bundled sources keep their license files (a -sys crate's C library: liblz4/lib/LICENSE).
MAX_DEPTH = 3
# Crates that build in a C library under a license their Cargo.toml does not name.
BUNDLED = {
    "lz4-sys": ("BSD-2-Clause", "The LZ4 C library it builds in is under the BSD-2-Clause (liblz4/lib/LICENSE)."),
}


def fail(message):
    sys.stderr.write(f"copyright.py: {message}\n")
    sys.exit(1)


def dep5_license(spdx, crate):
    """An SPDX expression from a Cargo.toml in DEP-5's words: 'MIT OR Apache-2.0' ->
    'MIT or Apache-2.0', '(A OR B) AND C' -> 'A or B, and C', 'A WITH X-exception' ->
    'A with X exception', the old 'MIT/Apache-2.0' -> 'MIT or Apache-2.0'."""
    expr = re.sub(r"\s*/\s*", " OR ", spdx.strip())

    def words(e):
        if "(" in e or ")" in e:
            fail(f"{crate}: license {spdx!r}: nested parentheses are not handled; extend dep5_license")
        e = re.sub(r"\s+WITH\s+(\S+?)-exception\b", r" with \1 exception", e)
        e = re.sub(r"\s+OR\s+", " or ", e)
        return re.sub(r"\s+AND\s+", " and ", e)

    m = re.fullmatch(r"\(([^()]*)\)\s+AND\s+(.*)", expr)
    if m:
        return f"{words(m.group(1))}, and {words(m.group(2))}"
    return words(expr)


def license_names(dep5):
    """The single licenses a DEP-5 License line names."""
    return [n for n in re.split(r",?\s+(?:and|or)\s+", dep5) if n]


def copyright_lines(crate_dir):
    """Copyright lines of the crate's license files, in order, each once."""
    found = []
    for root, dirs, files in os.walk(crate_dir):
        rel = os.path.relpath(root, crate_dir)
        depth = 0 if rel == "." else rel.count(os.sep) + 1
        dirs[:] = sorted(d for d in dirs if depth < MAX_DEPTH and d not in ("tests", "benches", "examples", "target"))
        for name in sorted(files):
            if not LICENSE_FILE.match(name):
                continue
            try:
                with open(os.path.join(root, name), encoding="utf-8", errors="replace") as f:
                    for line in f:
                        m = COPYRIGHT_LINE.match(line.strip())
                        if m and not TEMPLATE.search(line):
                            text = re.sub(r"\s+", " ", m.group(1)).strip()
                            text = re.sub(r"\s*All rights reserved\.?$", "", text, flags=re.I)
                            text = re.sub(r"^Copyright\s*(\(c\)|©)?\s*", "", text, flags=re.I)
                            if text and text not in found:
                                found.append(text)
            except OSError as e:
                fail(f"reading {os.path.join(root, name)}: {e}")
    return found


def field(name, lines):
    """A DEP-5 field whose value spans lines (continuations indented by one space)."""
    return f"{name}: {lines[0]}" + "".join(f"\n {line}" for line in lines[1:])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--metadata", required=True)
    ap.add_argument("--crates", required=True)
    ap.add_argument("--maintainer", required=True)
    ap.add_argument("--rustc", required=True)
    args = ap.parse_args()

    with open(args.metadata, encoding="utf-8") as f:
        meta = json.load(f)
    packages = {p["id"]: p for p in meta["packages"]}
    nodes = {n["id"]: n for n in meta["resolve"]["nodes"]}
    members = set(meta["workspace_members"])
    root_dir = meta["workspace_root"]

    wanted = set(args.crates.split(","))
    roots = [i for i in members if packages[i]["name"] in wanted]
    if len(roots) != len(wanted):
        fail(f"not workspace crates: {sorted(wanted - {packages[i]['name'] for i in roots})}")

    def build_time_only(p):
        return any("proc-macro" in t["kind"] for t in p["targets"])

    linked, stack = set(), list(roots)
    while stack:
        i = stack.pop()
        if i in linked:
            continue
        linked.add(i)
        for d in nodes[i]["deps"]:
            normal = any(k["kind"] is None for k in d["dep_kinds"])
            if normal and not build_time_only(packages[d["pkg"]]):
                stack.append(d["pkg"])

    with open(os.path.join(HERE, "copyright.in"), encoding="utf-8") as f:
        out = f.read().replace("@MAINTAINER@", args.maintainer).replace("@RUSTC@", args.rustc)
    out = out.rstrip("\n") + "\n"

    for p in sorted((packages[i] for i in linked - members), key=lambda p: (p["name"], p["version"])):
        name, version = p["name"], p["version"]
        crate_dir = os.path.dirname(p["manifest_path"])
        if not p.get("license"):
            fail(f"{name} {version} declares no license (license-file only): add it to copyright.in")
        if p["source"] is None:
            # A patched copy inside the workspace (third_party/, [patch.crates-io]).
            files = os.path.relpath(crate_dir, root_dir) + "/*"
            comment = [f"{name} {version} as published on crates.io, with the patch beside it",
                       f"({os.path.relpath(os.path.dirname(crate_dir), root_dir)}/README.md says what and why)."]
        else:
            files = f"crates-io/{name}-{version}/*"
            comment = None
        holders = copyright_lines(crate_dir) or list(p["authors"]) or [f"the {name} authors"]
        license = dep5_license(p["license"], name)
        if name in BUNDLED:
            license = f"{license}, and {BUNDLED[name][0]}"
            comment = (comment or []) + [BUNDLED[name][1]]
        lines = [field("Files", [files]), field("Copyright", holders), f"License: {license}"]
        if comment:
            lines.append(field("Comment", comment))
        out += "\n" + "\n".join(lines) + "\n"

    named = []
    for m in re.finditer(r"^License: (.*)$", out, re.M):
        for n in license_names(m.group(1)):
            if n not in named:
                named.append(n)
    for n in named:
        path = os.path.join(HERE, "licenses", n.replace(" ", "-"))
        if not os.path.isfile(path):
            fail(f"no text for the license {n!r}: add packaging/deb/licenses/{n.replace(' ', '-')}")
        with open(path, encoding="utf-8") as f:
            text = f.read().strip("\n").splitlines()
        body = [line.rstrip() if line.strip() else "." for line in text]
        out += f"\nLicense: {n}\n" + "".join(f" {line}\n" for line in body)

    sys.stdout.write(out)


if __name__ == "__main__":
    main()
