"""The mission-file key reference as Markdown, generated from the schema (`schema_reference`),
so that docs/mission-file.md cannot drift from what the loader accepts.

Regenerate it with ``python -m mexgen_gcs.config.reference > docs/mission-file.md``; a test
compares the file with this output. No frames here (positions keep the frames their key
descriptions name).
"""

from __future__ import annotations

import sys

from mexgen_gcs.config.describe import KeyDoc, schema_reference

HEADER = """\
Kind: reference

# Mission file keys

Every key of a mission file (`version: 1`), with its type, default, limits and meaning,
generated from the schema that `mexgen-gcs check` and every command load missions with
(`python -m mexgen_gcs.config.reference > docs/mission-file.md`; a test keeps this page equal
to that output). Conventions (units in key names, frames, headings), the example missions, the
rules across keys and the warnings are in [missions/README.md](../missions/README.md).

Types: *number* is an int or float literal, *integer* a whole number, *text* a string, *list
of X* a YAML sequence, *[number, number]* a two-element sequence. *limits* are checked at
load; *required* keys have no default. Unknown keys are errors.
"""


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _presence(default: str) -> str:
    return "required" if default == "required" else f"optional ({default})"


def _row(doc: KeyDoc) -> str:
    return (f"| `{doc.key}` | {_cell(doc.type)} | {_cell(doc.default)} | {_cell(doc.limits)} "
            f"| {_cell(doc.description)} |")


def markdown_reference() -> str:
    """The whole page: the top-level keys, then one table per section in schema order."""
    docs = list(schema_reference())
    sections = [d for d in docs if "." not in d.key
                and d.type.startswith(("mapping", "list of mapping"))]
    names = {d.key for d in sections}
    top = [d for d in docs if "." not in d.key and d.key not in names]
    out = [HEADER, "## Top level", "", "| key | type | default | limits | meaning |",
           "|---|---|---|---|---|", *(_row(d) for d in top)]
    for sec in sections:
        rows = [d for d in docs if d.key.startswith(sec.key + ".")
                or d.key.startswith(sec.key + "[]")]
        out += ["", f"## `{sec.key}`", "",
                f"`{sec.key}`: {_cell(sec.type)}, {_presence(sec.default)}. {sec.description}",
                "",
                "| key | type | default | limits | meaning |", "|---|---|---|---|---|",
                *(_row(d) for d in rows)]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.stdout.write(markdown_reference())
