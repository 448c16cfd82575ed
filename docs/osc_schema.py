"""Every action, condition, position type, distribution and storyboard element of the
OpenSCENARIO 1.3 XML schema, each with whether OpenSCENARIO 1.2 has it and whether 1.3
marks it deprecated: the standard's side of the coverage table (docs/openscenario.md),
which the importer's and exporter's registries are joined with.

    python docs/osc_schema.py [--format markdown|json] [--xsd-dir DIR]

The schemas are those of the ASAM OpenSCENARIO checker (the PyPI package
asam-qc-openscenarioxml, a test requirement: `qc_openscenario/schema/<version>/OpenSCENARIO.xsd`),
read where it is installed; `--xsd-dir` names a folder with `1.2.0/` and `1.3.0/` instead.
They are not copied here (ASAM's licence terms).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path

XS = "{http://www.w3.org/2001/XMLSchema}"
VERSIONS = ("1.2.0", "1.3.0")
# Types of the storyboard's structure, walked from <Storyboard> (their children are its elements).
STORYBOARD_TYPES = ("Storyboard", "Init", "InitActions", "Story", "Act", "ManeuverGroup", "Maneuver", "Event",
                    "Trigger", "ConditionGroup", "Private")
DISTRIBUTION_GROUPS = ("DistributionDefinition", "DeterministicParameterDistribution",
                       "DeterministicSingleParameterDistributionType", "DeterministicMultiParameterDistributionType",
                       "StochasticDistributionType")


@dataclass(frozen=True)
class Entry:
    category: str  # action | condition | position | distribution | storyboard
    path: str  # the element under its parents, e.g. PrivateAction/LongitudinalAction/SpeedAction
    in_1_2: bool
    deprecated: bool  # the 1.3 schema marks it <appinfo>deprecated</appinfo>

    @property
    def name(self) -> str:
        return self.path.rsplit("/", 1)[-1]


class Schema:
    def __init__(self, path: Path):
        root = ET.parse(path).getroot()
        self.types = {t.get("name"): t for t in root.iter(f"{XS}complexType") if t.get("name")}
        self.groups = {g.get("name"): g for g in root.iter(f"{XS}group") if g.get("name")}

    def children(self, node) -> list[tuple[str, str, bool]]:
        """(element name, its type, deprecated) of a complex type or group, groups resolved,
        in schema order; elements' own content is not entered."""
        out = []
        for child in node:
            if child.tag == f"{XS}element":
                deprecated = any((a.text or "").strip() == "deprecated" for a in child.iter(f"{XS}appinfo"))
                out.append((child.get("name"), child.get("type", ""), deprecated))
            elif child.tag == f"{XS}group" and child.get("ref"):
                out += self.children(self.groups[child.get("ref")])
            elif child.tag in (f"{XS}sequence", f"{XS}choice", f"{XS}all", f"{XS}complexContent", f"{XS}extension"):
                out += self.children(child)
        return out

    def of_type(self, name: str) -> list[tuple[str, str, bool]]:
        node = self.types.get(name)
        return self.children(node) if node is not None else []

    def leaves(self, type_name: str, suffix: str, prefix: str = "") -> list[tuple[str, bool]]:
        """Paths of the elements named `...suffix` under a type, descending while a child
        has such children itself (PrivateAction/LongitudinalAction/SpeedAction)."""
        out = []
        for name, typ, deprecated in self.of_type(type_name):
            if not name.endswith(suffix):
                continue
            path = f"{prefix}{name}"
            if any(n.endswith(suffix) for n, _, _ in self.of_type(typ)):
                out += [(p, d or deprecated) for p, d in self.leaves(typ, suffix, path + "/")]
            else:
                out.append((path, deprecated))
        return out

    def entries(self) -> dict[tuple[str, str], bool]:
        """(category, path) -> deprecated."""
        found: dict[tuple[str, str], bool] = {}
        for path, dep in self.leaves("Action", "Action"):
            found[("action", path)] = dep
        for path, dep in self.leaves("Condition", "Condition"):
            found[("condition", path)] = dep
        for name, _, dep in self.of_type("Position"):
            found[("position", name)] = dep
        for group in DISTRIBUTION_GROUPS:
            for name, _, dep in self.children(self.groups.get(group, ET.Element("none"))):
                found[("distribution", f"{group}/{name}")] = dep
        for parent in STORYBOARD_TYPES:
            for name, _, dep in self.of_type(parent):
                found[("storyboard", f"{parent}/{name}")] = dep
        return found


def xsd_dir() -> Path:
    spec = importlib.util.find_spec("qc_openscenario")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("asam-qc-openscenarioxml is not installed (pip install --no-deps -r "
                         "tests/requirements-opendrive-checker.txt), or give --xsd-dir")
    return Path(next(iter(spec.submodule_search_locations))) / "schema"


def table(directory: Path | None = None) -> list[Entry]:
    """The 1.3 schema's entries, with 1.2's membership, sorted by category and path."""
    directory = directory or xsd_dir()
    old, new = (Schema(directory / v / "OpenSCENARIO.xsd").entries() for v in VERSIONS)
    # By the whole path: VariableAction/SetAction is not ParameterAction/SetAction.
    return sorted((Entry(c, p, (c, p) in old, dep) for (c, p), dep in new.items()),
                  key=lambda e: (e.category, e.path))


def markdown(entries: list[Entry]) -> str:
    lines = ["| category | element | in 1.2 | deprecated in 1.3 |", "|---|---|---|---|"]
    lines += [f"| {e.category} | `{e.path}` | {'yes' if e.in_1_2 else 'no (1.3)'} | {'yes' if e.deprecated else ''} |"
              for e in entries]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--format", choices=("markdown", "json"), default="markdown")
    parser.add_argument("--xsd-dir", type=Path, help="a folder with 1.2.0/OpenSCENARIO.xsd and 1.3.0/OpenSCENARIO.xsd")
    args = parser.parse_args(argv)
    entries = table(args.xsd_dir)
    if args.format == "json":
        sys.stdout.write(json.dumps([{**asdict(e), "name": e.name} for e in entries], indent=1) + "\n")
    else:
        sys.stdout.write(markdown(entries))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
