#!/usr/bin/env python3
"""The floors of polyspline: no import cycle between top-level modules, no import up a floor.

    scripts/check_floors.py [--edges] [--root DIR]

Reads every `src/**/*.rs` (the library, and the binary's `main.rs` and `cli/`), resolves each
path that names the crate (`crate::…`, `super::…`, `self::…`, a child module's name, in the
binary `polyspline::…`), in `use` trees and in code alike (comments and string literals are
skipped), to the top-level module it enters, and checks against FLOORS below:

  1. every top-level module of `src/lib.rs` has a floor (and every module of FLOORS exists);
  2. a module imports only modules of its own floor or of floors below it, and neither of two
     side-by-side floors (SIBLINGS) imports the other;
  3. the graph between top-level modules has no cycle (imports within one floor included);
  4. the library names no clap path (the command line spells its values, `src/cli/values.rs`);
  5. the library neither prints nor exits (`print!`, `println!`, `eprint!`, `eprintln!`,
     `dbg!`, `process::exit`, `process::abort` outside its `mod tests`): it returns typed
     errors and reports, and the binary (`main.rs`, `cli/`) prints them and sets the status.

Prints one line per violation, with the file and line of every import that makes it, and
exits 1 if there is any; `--edges` also lists every edge between top-level modules. Python 3
standard library only; `tests/library/floors.rs` runs it.
"""
import argparse
import os
import re
import sys

# The floors, bottom up: a module may import its own floor and those below it. One place for
# the table (docs/architecture.md and src/lib.rs describe it in words).
FLOORS = [
    ("foundation", ["math", "params", "progress"]),
    ("mesh", ["mesh"]),
    ("io", ["io", "plot"]),
    ("algorithms", ["spline", "solve", "fit", "validity", "energy", "elastic", "sample",
                    "deviation", "quality", "info"]),
    ("execution", ["exec"]),
    ("jobs", ["pipeline", "compare", "distributed"]),
    ("cli", ["cli"]),
]

# Floors that sit side by side: neither may import the other (the job floor composes them).
SIBLINGS = [("io", "algorithms")]

# Macros by which a library would print (rule 5).
PRINTS = ("print", "println", "eprint", "eprintln", "dbg")

IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
DOC_PATH = re.compile(r"\bcrate(?:::[A-Za-z_][A-Za-z0-9_]*)+")


def tokens(text):
    """(token, line) pairs of Rust source without comments, string or char literals."""
    out = []
    i, n, line = 0, len(text), 1
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif c.isspace():
            i += 1
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            if text.startswith(("///", "//!"), i):
                # Paths in doc comments are links rustdoc resolves: they count as imports.
                for m in DOC_PATH.finditer(text, i, j):
                    out.append(("@doc", line))
                    for seg in m.group(0).split("::"):
                        out.append((seg, line))
                        out.append(("::", line))
                    out.pop()
                    out.append(("@end", line))
            i = j
        elif text.startswith("/*", i):
            depth, i = 1, i + 2
            while i < n and depth:
                if text.startswith("/*", i):
                    depth, i = depth + 1, i + 2
                elif text.startswith("*/", i):
                    depth, i = depth - 1, i + 2
                else:
                    line += text[i] == "\n"
                    i += 1
        elif c == '"' or (c in "rb" and re.match(r'(b?r#*"|b")', text[i:i + 8])):
            m = re.match(r'(b?)(r?)(#*)"', text[i:])
            raw, hashes = m.group(2), m.group(3)
            i += m.end()
            end = '"' + hashes
            while i < n:
                if not raw and text[i] == "\\":
                    line += text[i + 1] == "\n"
                    i += 2
                elif text.startswith(end, i):
                    i += len(end)
                    break
                else:
                    line += text[i] == "\n"
                    i += 1
        elif c == "'":
            # A char literal ('a', '\n', '\u{..}') or a lifetime ('a).
            m = re.match(r"'(\\.[^']*|[^\\'])'", text[i:])
            if m:
                i += m.end()
            else:
                m = IDENT.match(text, i + 1)
                i = m.end() if m else i + 1
        elif text.startswith("::", i):
            out.append(("::", line))
            i += 2
        elif IDENT.match(text, i):
            m = IDENT.match(text, i)
            out.append((m.group(0), line))
            i = m.end()
        else:
            out.append((c, line))
            i += 1
    return out


def module_path(rel):
    """Module path of a source file relative to src/ ("fit/mod.rs" → ["fit"])."""
    parts = rel[:-3].split("/")
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return parts


def use_trees(toks, k):
    """Paths of the `use` tree starting at toks[k]; returns (paths, index after the tree)."""
    prefix = []
    while k < len(toks):
        t = toks[k][0]
        if t == "{":
            paths, k = [], k + 1
            while toks[k][0] != "}":
                sub, k = use_trees(toks, k)
                paths += [(prefix + p, ln) for p, ln in sub]
                if toks[k][0] == ",":
                    k += 1
            return paths, k + 1
        if t == "*":
            return [(prefix, toks[k][1])], k + 1
        if IDENT.fullmatch(t) or t == "$crate":
            prefix.append(t)
            k += 1
            if k < len(toks) and toks[k][0] == "::":
                k += 1
                continue
            line = toks[k - 1][1]
            if k < len(toks) and toks[k][0] == "as":
                k += 2
            return [(prefix, line)], k
        return [(prefix, toks[k][1])], k
    return [(prefix, 0)], k


def resolve(path, here, children, roots):
    """The absolute module path a path names (`crate::a::b` from module `here`), or None."""
    if not path:
        return None
    head = path[0]
    if head == "crate":
        return path[1:]
    if head in ("super", "self"):
        cur = list(here)
        i = 0
        while i < len(path) and path[i] in ("super", "self"):
            if path[i] == "super":
                if not cur:
                    return None
                cur.pop()
            i += 1
        return cur + path[i:]
    if head in roots:
        return roots[head] + path[1:]
    if head in children.get(tuple(here), ()):
        return list(here) + path
    return None


def scan(src, lib_modules):
    """Every crate path named in src/: list of (file, line, absolute path, crate)."""
    files = []
    for dirpath, _, names in os.walk(src):
        for name in names:
            if name.endswith(".rs"):
                files.append(os.path.relpath(os.path.join(dirpath, name), src))
    files.sort()
    children = {}
    for rel in files:
        mp = module_path(rel)
        if mp:
            children.setdefault(tuple(mp[:-1]), set()).add(mp[-1])
    refs = []
    for rel in files:
        binary = rel == "main.rs" or rel.startswith("cli/")
        base = module_path(rel)
        roots = {"polyspline": []} if binary else {}
        toks = tokens(open(os.path.join(src, rel), encoding="utf-8").read())
        # Inline modules (`mod tests { … }`) move `super` and `self` one level down.
        stack, depth = [], 0
        k = 0
        while k < len(toks):
            t, line = toks[k]
            here = base + [m for m, _ in stack]
            if t == "mod" and k + 2 < len(toks) and toks[k + 2][0] == "{":
                stack.append((toks[k + 1][0], depth))
                depth += 1
                k += 3
                continue
            if t == "{":
                depth += 1
            elif t == "}":
                depth -= 1
                if stack and stack[-1][1] == depth:
                    stack.pop()
            in_tests = any(m == "tests" for m, _ in stack)
            if not binary and not in_tests:
                nxt = toks[k + 1][0] if k + 1 < len(toks) else ""
                if t in PRINTS and nxt == "!":
                    refs.append((rel, line, ["@print", t + "!"], binary))
                elif t == "process" and nxt == "::" and k + 2 < len(toks) and toks[k + 2][0] in ("exit", "abort"):
                    refs.append((rel, line, ["@print", "process::" + toks[k + 2][0]], binary))
            if t == "clap" and not binary and k + 1 < len(toks) and toks[k + 1][0] == "::":
                refs.append((rel, line, ["@clap"], binary))
            if t == "use":
                paths, k = use_trees(toks, k + 1)
                for p, ln in paths:
                    full = resolve(p, here, children, roots)
                    if full:
                        refs.append((rel, ln, full, binary))
                continue
            prev = toks[k - 1][0] if k else ""
            if t in ("crate", "super", "self", *roots) and prev != "::" and k + 1 < len(toks) \
                    and toks[k + 1][0] == "::" and prev != "in":
                path = [t]
                j = k + 1
                while j + 1 < len(toks) and toks[j][0] == "::" and IDENT.fullmatch(toks[j + 1][0]):
                    path.append(toks[j + 1][0])
                    j += 2
                full = resolve(path, here, children, roots)
                if full:
                    refs.append((rel, line, full + (["(doc link)"] if prev == "@doc" else []), binary))
                k = j
                continue
            k += 1
    return refs


def lib_modules(src):
    text = open(os.path.join(src, "lib.rs"), encoding="utf-8").read()
    return re.findall(r"^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+([a-z_0-9]+)\s*;", text, re.M)


def top_of(rel, binary):
    if binary:
        return "cli"
    return module_path(rel)[0]


def sccs(nodes, edges):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, on, stack, out = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ap.add_argument("--edges", action="store_true", help="list every edge between top-level modules")
    args = ap.parse_args()
    src = os.path.join(args.root, "src")
    floor_of = {m: (i, name) for i, (name, mods) in enumerate(FLOORS) for m in mods}
    mods = lib_modules(src)
    problems = []
    for m in mods:
        if m not in floor_of:
            problems.append(f"module `{m}` of src/lib.rs has no floor in scripts/check_floors.py")
    for m in floor_of:
        if m != "cli" and m not in mods:
            problems.append(f"floor table names `{m}`, which src/lib.rs does not declare")
    edges, where = {}, {}
    for rel, line, full, binary in scan(src, mods):
        if full == ["@clap"]:
            problems.append(f"src/{rel}:{line}: the library names clap; spell the value in src/cli/")
            continue
        if full[0] == "@print":
            problems.append(f"src/{rel}:{line}: the library calls {full[1]}; return an error or a report and let the binary (src/cli/) print or exit")
            continue
        a = top_of(rel, binary)
        b = full[0] if full else None
        if b is None or b == a or b not in floor_of:
            continue
        edges.setdefault(a, set()).add(b)
        where.setdefault((a, b), []).append(f"src/{rel}:{line} {'::'.join(full)}")
    sibling = {(x, y) for x, y in SIBLINGS} | {(y, x) for x, y in SIBLINGS}
    for (a, b), sites in sorted(where.items()):
        fa, fb = floor_of[a], floor_of[b]
        if fb[0] > fa[0] or (fa[1], fb[1]) in sibling:
            what = "up a floor" if fb[0] > fa[0] else "across to a sibling floor"
            problems.append(f"`{a}` ({fa[1]}) imports `{b}` ({fb[1]}), {what}:\n    " + "\n    ".join(sites))
    for comp in sccs(set(floor_of), edges):
        ties = [f"{a} -> {b}: {where[(a, b)][0]}" for a in comp for b in sorted(edges.get(a, ())) if b in comp]
        problems.append(f"import cycle between {', '.join(comp)}:\n    " + "\n    ".join(ties))
    if args.edges:
        for (a, b), sites in sorted(where.items()):
            print(f"{a} -> {b}  ({len(sites)}: {sites[0]})")
    for p in problems:
        print(p)
    print(f"{len(problems)} floor violation(s)" if problems else
          f"floors hold: {len(mods)} modules on {len(FLOORS)} floors, no cycle, no import up a floor")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
