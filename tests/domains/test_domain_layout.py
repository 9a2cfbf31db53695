"""What a domain must provide: one folder `domains/<name>/` plus one registry line.

`FOLDER` below is the list (docs/domains.md, "A domain's folder", shows the same): what the
`Domain` base class, the registry, the authoring loop (`rivet author` replays
`transcripts/reference/`, shows `programs/` as the reference), the checks' mutation benchmark
(`mutants.toml`) and the benchmark sets read from a domain's folder. `CLASS` is what its
`Domain` subclass must define itself. The registry line is the domain's name in
`domains/__init__.py`'s `from domains import …`. Nothing else in the repository names a
domain: its frozen programs (`artifacts/<name>/`) are what `rivet author` writes.
"""

from __future__ import annotations

import ast
import json
import tomllib
from pathlib import Path

import pytest

import domains
from checks.properties.library import LIBRARY
from contracts.functions import FUNCTIONS
from domains.base import CAMERA_NAMES, Domain
from domains.benchmark import BENCHMARK_GOALS, BENCHMARK_STARTS, benchmark_keys, benchmark_name

ROOT = Path(domains.__file__).parent

# path in the folder → what it is for (a trailing "/" marks a folder)
FOLDER = {
    "__init__.py": "the Domain subclass, registered by name: generators of goals and starts",
    "task.md": "the task text a model is told (`Domain.task`)",
    "catalogue.json": "objects (id, mesh, colour, mass, friction) and meshes (file, convex "
    "collision parts, symmetry group, frame in words)",
    "cameras.json": f"the cameras {', '.join(CAMERA_NAMES)} (the first is the default)",
    "tolerances.json": "the scoring tolerances (translation_m, rotation_deg or null)",
    "make_meshes.py": "`build()` → the meshes (and their convex parts) that meshes/ holds",
    "meshes/": "the OBJ files the catalogue names, nothing else",
    "benchmark/": f"the dev split: goalGG_startS.json, {BENCHMARK_GOALS} goals × "
    f"{BENCHMARK_STARTS} starts",
    "benchmark/test/": "the test split, the same names and size",
}
# optional extras: a domain without them is authored by a model (`rivet author D --model …`);
# with them it also replays offline and takes part in the mutation benchmark
OPTIONAL = {
    "programs/": "people-written reference programs render.py, perceive.py, relate.py, "
    "plan.py (earlier failing versions in drafts/<function>_v<k>.py)",
    "transcripts/reference/": "the transcript `rivet author DOMAIN` replays (meta.json and "
    "the responses it lists), packed from programs/",
    "mutants.toml": "the checks' mutation benchmark: bugs planted in programs/",
}
# what the Domain subclass defines itself (the rest has defaults in `domains.base.Domain`:
# the reference relations and their gaps, workspace, placement region, `properties` — the
# domain properties its drafts are checked for, by function, from `checks.properties`)
CLASS = ("name", "root", "make_goal", "make_start")

NAMES = domains.names()


def _packages() -> set[str]:
    return {
        p.name
        for p in ROOT.iterdir()
        if (p / "__init__.py").is_file() and not p.name.startswith("_")
    }


def test_every_domain_folder_is_registered_by_one_line():
    tree = ast.parse((ROOT / "__init__.py").read_text())
    lines = [
        node
        for node in tree.body
        if isinstance(node, ast.ImportFrom)
        and node.module == "domains"
        and {a.name for a in node.names} & _packages()
    ]
    assert len(lines) == 1, "domains/__init__.py imports the domain packages in one line"
    assert {a.name for a in lines[0].names} == _packages() == set(NAMES)
    for name in NAMES:
        cls = type(domains.load(name))
        assert cls.__module__ == f"domains.{name}", name
        assert cls.name == name and Path(cls.root) == ROOT / name, name


@pytest.fixture(scope="module", params=NAMES)
def domain(request) -> Domain:
    return domains.load(request.param)


def test_the_folder_holds_what_a_domain_needs(domain):
    folder = domain.root
    missing = [p for p in FOLDER if not _exists(folder / p.rstrip("/"), p.endswith("/"))]
    assert not missing, f"{domain.name}: missing {missing}"


def test_the_optional_extras_come_together(domain):
    """A transcript is packed from programs, and mutants are planted in them: neither without
    the programs."""
    held = {p for p in OPTIONAL if _exists(domain.root / p.rstrip("/"), p.endswith("/"))}
    if "programs/" not in held:
        assert not held, f"{domain.name}: {sorted(held)} without programs/"


def _exists(path: Path, is_dir: bool) -> bool:
    return path.is_dir() if is_dir else path.is_file()


def test_meshes_are_exactly_the_catalogues(domain):
    cat = json.loads((domain.root / "catalogue.json").read_text())
    named = {m["file"] for m in cat["meshes"].values()}
    named |= {f for m in cat["meshes"].values() for f in m["collision"]}
    held = {f"meshes/{p.name}" for p in (domain.root / "meshes").iterdir()}
    assert held == named, f"{domain.name}: meshes/ {sorted(held ^ named)}"
    assert list(json.loads((domain.root / "cameras.json").read_text())) == list(CAMERA_NAMES)
    assert set(json.loads((domain.root / "tolerances.json").read_text())) == {
        "translation_m",
        "rotation_deg",
    }


def test_the_benchmark_sets_hold_every_pair(domain):
    for split in ("dev", "test"):
        files = {p.name for p in domain.benchmark_dir_of(split).glob("*.json")}
        names = {
            benchmark_name(g, s, split).rpartition("/")[2] + ".json" for g, s in benchmark_keys()
        }
        assert files == names, f"{domain.name} {split}: {sorted(files ^ names)}"


def test_programs_transcript_and_mutants(domain):
    if not (domain.root / "programs").is_dir():
        pytest.skip(f"{domain.name} has no people-written programs (an optional extra)")
    programs = domain.root / "programs"
    assert {p.name for p in programs.glob("*.py")} == {f"{f}.py" for f in FUNCTIONS}
    assert {p.name for p in programs.iterdir() if p.name != "__pycache__"} <= {
        *(f"{f}.py" for f in FUNCTIONS),
        "drafts",
    }
    for draft in (programs / "drafts").glob("*"):
        function, _, version = draft.stem.rpartition("_v")
        assert function in FUNCTIONS and version.isdigit() and draft.suffix == ".py", draft

    reference = domain.reference_transcript
    meta = json.loads((reference / "meta.json").read_text())
    assert meta["domain"] == domain.name
    listed = {r["file"] for r in meta["responses"]}
    assert {r["function"] for r in meta["responses"]} == set(FUNCTIONS)
    assert {p.name for p in reference.iterdir()} == {"meta.json", *listed}

    mutants = tomllib.loads((domain.root / "mutants.toml").read_text())
    assert mutants["domain"] == domain.name
    assert mutants["mutant"] and {m["function"] for m in mutants["mutant"]} <= set(FUNCTIONS)


def test_nothing_else_is_in_the_folder_but_the_domains_own_code_and_the_data_it_reads(domain):
    folder = domain.root
    required = {p.rstrip("/").partition("/")[0] for p in {**FOLDER, **OPTIONAL}}
    code = "\n".join(p.read_text() for p in folder.glob("*.py"))
    for entry in folder.iterdir():
        if entry.name in required or entry.name == "__pycache__":
            continue
        # a module of the domain's package, or a file its modules read by name
        assert entry.suffix == ".py" or f'"{entry.name}"' in code, (
            f"{domain.name}: {entry.name} is neither required (FOLDER) nor read by the domain"
        )


def test_the_domain_class_defines_what_the_base_class_needs(domain):
    cls = type(domain)
    own = {k for c in cls.__mro__ if c is not Domain and issubclass(c, Domain) for k in vars(c)}
    assert set(CLASS) <= own, f"{cls.__name__} lacks {sorted(set(CLASS) - own)}"
    assert cls.make_goal is not Domain.make_goal and cls.make_start is not Domain.make_start
    # domain properties are registered by the domain: known functions, names of the library
    assert set(domain.properties) <= set(FUNCTIONS)
    for function, props in domain.properties.items():
        for name, params in props:
            assert name in LIBRARY, f"{domain.name}.{function}: unknown property {name!r}"
            assert isinstance(params, dict)
