"""The documentation generated from `io.records`: JSON Schemas of the flight log and the truth
file (docs/schemas/) and the tables of record types in docs/flight-log.md and
docs/truth-file.md (between the GENERATED markers; the prose around them is written by hand).

    python -m mexgen_gcs.io.record_docs            # rewrite the generated files and sections
    python -m mexgen_gcs.io.record_docs --check    # exit 1 if any is out of date

No frames here (each field carries its own, from `io.records`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from pydantic import TypeAdapter

from mexgen_gcs.io import records as r

BEGIN = "<!-- BEGIN GENERATED from mexgen_gcs/io/records.py: do not edit by hand -->"
END = "<!-- END GENERATED -->"


def json_schema(adapter: TypeAdapter[Any], name: str, version: int, title: str) -> dict[str, Any]:
    """A JSON Schema (2020-12) of one line of a file: any of its record types."""
    body = adapter.json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": f"{name}-v{version}.schema.json", "title": title,
            "description": f"One line of a {name} file, format version {version}: a JSON "
                           "object with t and type; the first line is the header record. "
                           "Generated from mexgen_gcs/io/records.py.", **body}


def schemas() -> dict[str, dict[str, Any]]:
    """File name under docs/schemas/ -> schema."""
    return {
        f"flight-log-v{r.FLIGHT_LOG_VERSION}.schema.json": json_schema(
            r.FLIGHT_ADAPTER, "flight-log", r.FLIGHT_LOG_VERSION, "mexgen-gcs flight log record"),
        f"truth-v{r.TRUTH_VERSION}.schema.json": json_schema(
            r.TRUTH_ADAPTER, "truth", r.TRUTH_VERSION, "mexgen-gcs simulator truth record"),
    }


def _type_text(prop: dict[str, Any]) -> str:
    if "const" in prop:
        return f"`{json.dumps(prop['const'])}`"
    if "enum" in prop:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in prop["enum"])
    if "anyOf" in prop:
        parts = [_type_text(p) for p in prop["anyOf"]]
        return " or ".join(dict.fromkeys(parts))
    if "$ref" in prop:
        return f"object ({prop['$ref'].rsplit('/', 1)[-1]})"
    kind = prop.get("type", "any")
    if kind == "array":
        if "prefixItems" in prop:
            inner = ", ".join(_type_text(p) for p in prop["prefixItems"])
            return f"[{inner}]"
        return f"list of {_type_text(prop.get('items', {}))}"
    if kind == "object":
        values = prop.get("additionalProperties")
        return f"object of {_type_text(values)}" if isinstance(values, dict) else "object"
    return str(kind)


def _range_text(prop: dict[str, Any]) -> str:
    bounds = [f"{sign} {prop[key]:g}" for key, sign in (
        ("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
        ("exclusiveMaximum", "<")) if key in prop]
    for alt in prop.get("anyOf", []):
        bounds += [b for b in _range_text(alt).split(", ") if b]
    return ", ".join(bounds)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def record_table(model: type[r.Record]) -> str:
    """A markdown section for one record type: its doc and a table of its fields."""
    schema = model.model_json_schema()
    props: dict[str, Any] = schema["properties"]
    required = set(schema.get("required", []))
    type_name = props["type"].get("const", "?")
    lines = [f"### `{type_name}`", "", (model.__doc__ or "").strip(), "",
             "| field | type | unit | frame | required | range | meaning |",
             "|---|---|---|---|---|---|---|"]
    for name, prop in props.items():
        if name == "type":
            continue
        nullable = any(p.get("type") == "null" for p in prop.get("anyOf", []))
        need = "yes" if name in required else "no"
        if nullable and name in required:
            need = "yes (may be null)"
        lines.append("| " + " | ".join(_cell(c) for c in (
            f"`{name}`", _type_text(prop), prop.get("unit", ""), prop.get("frame", ""), need,
            _range_text(prop), prop.get("description", ""))) + " |")
    if schema.get("additionalProperties", True):
        lines += ["", "Other fields may follow" + (
            " (they depend on `kind`)." if "kind" in props else "; readers ignore them.")]
    return "\n".join(lines)


def tables(models: tuple[type[r.Record], ...]) -> str:
    return "\n\n".join(record_table(m) for m in models)


def generated_docs() -> dict[str, str]:
    """docs/ file name -> its generated section."""
    return {"flight-log.md": tables(r.FLIGHT_RECORDS), "truth-file.md": tables(r.TRUTH_RECORDS)}


def splice(text: str, section: str, where: str) -> str:
    """`text` with the part between the markers replaced by `section`."""
    if BEGIN not in text or END not in text:
        raise ValueError(f"{where}: no generated section (expected the markers {BEGIN} and "
                         f"{END})")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n\n{section}\n\n{END}{tail}"


def expected_files(docs: Path) -> dict[Path, str]:
    """Every generated file under `docs` with the content it should have."""
    out = {docs / "schemas" / name: json.dumps(schema, indent=2) + "\n"
           for name, schema in schemas().items()}
    for name, section in generated_docs().items():
        path = docs / name
        out[path] = splice(path.read_text(encoding="utf-8"), section, str(path))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mexgen_gcs.io.record_docs",
                                     description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--docs", default="docs", help="the docs directory (default: docs)")
    parser.add_argument("--check", action="store_true", help="only say what is out of date")
    args = parser.parse_args(argv)
    stale = []
    for path, content in expected_files(Path(args.docs)).items():
        if not path.exists() or path.read_text(encoding="utf-8") != content:
            stale.append(path)
            if not args.check:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(content, encoding="utf-8")
    for path in stale:
        print(f"{'out of date' if args.check else 'wrote'}: {path}", file=sys.stderr)
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    raise SystemExit(main())
