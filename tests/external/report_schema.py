"""Check `polyspline curve --report` files against docs/curve-report.schema.json.

Usage: report_schema.py SCHEMA [--may-miss DEF ...] REPORT...

The oracle is the `jsonschema` package (Draft 2020-12). Besides validating every report, it
checks the schema itself: a valid 2020-12 schema; every object closed
(`additionalProperties: false`, so a field the program writes and the schema does not list is
an error) and every property described. Coverage: every object of `$defs` must appear in at
least one report (an object with exactly its properties), so the closed objects are exercised;
`--may-miss` names the ones the caller could not produce (e.g. `adapter` without a GPU).
Prints one line per problem and exits 1 on any; prints `ok N reports` otherwise.
"""

import json
import sys

import jsonschema


def walk_schema(node, where, problems):
    """Every object schema closed, every property described."""
    if isinstance(node, dict):
        if node.get("type") == "object" and "properties" in node:
            if node.get("additionalProperties") is not False:
                problems.append(f"schema {where}: object without additionalProperties: false")
            for key, sub in node["properties"].items():
                if not str(sub.get("description", "")).strip():
                    problems.append(f"schema {where}.{key}: no description")
        for key, sub in node.items():
            walk_schema(sub, f"{where}.{key}", problems)
    elif isinstance(node, list):
        for i, sub in enumerate(node):
            walk_schema(sub, f"{where}[{i}]", problems)


def key_sets(value, out):
    """The key sets of every object in a JSON value."""
    if isinstance(value, dict):
        out.add(frozenset(value))
        for sub in value.values():
            key_sets(sub, out)
    elif isinstance(value, list):
        for sub in value:
            key_sets(sub, out)


def main(argv):
    schema_path, rest = argv[0], argv[1:]
    may_miss, reports = set(), []
    while rest:
        if rest[0] == "--may-miss":
            may_miss.add(rest[1])
            rest = rest[2:]
        else:
            reports.append(rest[0])
            rest = rest[1:]
    with open(schema_path) as f:
        schema = json.load(f)
    problems = []
    try:
        jsonschema.Draft202012Validator.check_schema(schema)
    except jsonschema.SchemaError as e:
        problems.append(f"schema: not a valid 2020-12 schema: {e.message}")
    walk_schema(schema, "#", problems)
    validator = jsonschema.Draft202012Validator(schema)
    seen = set()
    for path in reports:
        with open(path) as f:
            report = json.load(f)
        for e in validator.iter_errors(report):
            at = "/".join(map(str, e.absolute_path)) or "(root)"
            problems.append(f"{path}: {at}: {e.message[:300]}")
        key_sets(report, seen)
    for name, d in schema.get("$defs", {}).items():
        if d.get("type") == "object" and name not in may_miss:
            if frozenset(d["properties"]) not in seen:
                problems.append(f"coverage: no report holds a `{name}` object")
    for p in problems:
        print(p)
    if problems:
        return 1
    print(f"ok {len(reports)} reports")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
