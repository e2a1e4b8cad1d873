"""On-disk format of FE clamping cases and sweeps.

One case is two files sharing a stem (``{material}_t{thickness_mm:.2f}``, e.g. ``mr_t0.80``):

* ``<stem>.csv`` -- one row per converged load step (columns and units in
  :data:`COLUMN_UNITS`);
* ``<stem>.json`` -- the sidecar: case parameters, status, FE record, provenance, the
  SHA-256 of the CSV bytes and of the inputs.

Both are written atomically (temporary file in the same directory, then :func:`os.replace`;
see :mod:`grasprom.fe.atomicio`), the CSV first and the JSON last, so the presence of a JSON
sidecar marks a finished case. A failed case leaves ``<stem>.error.txt`` instead. A sweep
directory also holds a ``sweep.json`` manifest (see :func:`write_manifest`).

Units: lengths in mm, forces in N, stresses in MPa, times in s.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from grasprom import __version__
from grasprom.fe.atomicio import atomic_write_bytes, atomic_write_json, json_default
from grasprom.fe.model2d import COLUMN_DESCRIPTIONS, CONTRACT_COLUMNS, CaseResult, CaseSpec
from grasprom.fe.model3d import COLUMN_DESCRIPTIONS_3D
from grasprom.fe.provenance import now_iso, provenance

SCHEMA_VERSION = 1
"""Version of the case sidecar and manifest layout; bump on incompatible change."""

MANIFEST_NAME = "sweep.json"
"""File name of the sweep manifest inside a sweep directory."""

ERROR_SUFFIX = ".error.txt"
"""Suffix of the file recording a failed case (``<stem>.error.txt``)."""

VALID_STATUSES = ("complete", "partial")
"""Statuses a finished case may carry (see :class:`grasprom.fe.model2d.CaseResult`)."""

REQUIRED_COLUMNS = CONTRACT_COLUMNS
"""Columns every case CSV must hold."""

COLUMN_UNITS = {
    k: v.split(",")[0] for k, v in {**COLUMN_DESCRIPTIONS, **COLUMN_DESCRIPTIONS_3D}.items()
}
"""Units of the known CSV columns of both models (``"1"`` = dimensionless)."""

SPEC_UNITS = {
    "thickness_mm": "mm",
    "diameter_mm": "mm",
    "jaw_length_mm": "mm",
    "closed_gap_mm": "mm",
    "force_cap_N": "N",
    "wall_time_s": "s",
}
"""Units of the scalar sidecar keys."""

_STEM_RE = re.compile(r"^(?P<material>[A-Za-z0-9]+)_t(?P<thickness>\d+\.\d+)$")


class CorruptCaseError(Exception):
    """A case file on disk is unreadable or inconsistent.

    Parameters
    ----------
    path : str or os.PathLike
        The offending file.
    reason : str
        What is wrong with it.
    """

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(
            f"corrupt case file {self.path}: {reason} "
            "(the file was left untouched; move it away or repair it, then rerun)"
        )

    def __reduce__(self):  # keep picklable despite the custom signature
        return (type(self), (str(self.path), self.reason))


@dataclass(frozen=True)
class CaseFiles:
    """Paths of one case's files.

    Attributes
    ----------
    csv : pathlib.Path
        ``<stem>.csv``, one row per load step.
    json : pathlib.Path
        ``<stem>.json`` sidecar.
    """

    csv: Path
    json: Path


@dataclass(frozen=True)
class LoadedCase:
    """A validated case read back from disk.

    Attributes
    ----------
    meta : dict
        The parsed JSON sidecar.
    table : pandas.DataFrame
        The load-step table (units in ``meta["units"]``).
    files : CaseFiles
        Where it was read from.
    """

    meta: dict
    table: pd.DataFrame
    files: CaseFiles


# --------------------------------------------------------------------------- naming / hashing


def case_stem(material: str, thickness_mm: float) -> str:
    """File stem of a case, ``{material}_t{thickness_mm:.2f}``.

    Parameters
    ----------
    material : str
        Material key (``"mr"``, ``"nh"``, ``"le"``).
    thickness_mm : float
        Wall thickness in mm.

    Returns
    -------
    str
        E.g. ``"mr_t0.80"``.
    """
    return f"{material}_t{thickness_mm:.2f}"


def spec_stem(spec: CaseSpec) -> str:
    """File stem of a :class:`~grasprom.fe.model2d.CaseSpec` (see :func:`case_stem`)."""
    return case_stem(spec.material, spec.thickness_mm)


def parse_stem(stem: str) -> tuple[str, float] | None:
    """Invert :func:`case_stem`.

    Returns
    -------
    tuple of (str, float) or None
        ``(material, thickness_mm)``, or None if ``stem`` is not a case stem.
    """
    m = _STEM_RE.match(stem)
    if m is None:
        return None
    return m["material"], float(m["thickness"])


def case_files(directory: str | os.PathLike[str], stem: str) -> CaseFiles:
    """Paths of the case ``stem`` inside ``directory``."""
    d = Path(directory)
    return CaseFiles(csv=d / f"{stem}.csv", json=d / f"{stem}.json")


def canonical_json(obj: Any) -> str:
    """Deterministic compact JSON (sorted keys) used for hashing."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=json_default)


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of ``data``."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | os.PathLike[str]) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


NEUTRAL_FIELDS = (
    ("mesh", "far_coarsening", 1),
    ("solver", "unload_from_N", 0.0),
    ("solver", "band_companion", 0),
)
"""``(group, field, value)`` of spec fields added after data was written without them: at this
value a field is left out of :func:`spec_record` (the value the files written before it were
computed with), so those files stay current for a resumed sweep and for the manifest checks."""


def spec_record(spec: CaseSpec) -> dict[str, Any]:
    """``asdict(spec)`` without the :data:`NEUTRAL_FIELDS` that hold their neutral value: what
    the sidecar records as ``spec`` and :func:`input_hash` hashes."""
    d = dataclasses.asdict(spec)
    for group, name, value in NEUTRAL_FIELDS:
        sub = d.get(group)
        if isinstance(sub, dict) and name in sub and sub[name] == value:
            del sub[name]
    return d


def input_hash(spec: CaseSpec) -> str:
    """Hash of a case's inputs: SHA-256 of the canonical JSON of :func:`spec_record`.

    Two specs with equal fields (material, geometry, mesh, solver settings) hash equally;
    this is what a resumed sweep compares against the finished files on disk.
    """
    return sha256_bytes(canonical_json(spec_record(spec)).encode())


def input_mismatch(meta: Mapping[str, Any], spec: CaseSpec) -> str | None:
    """How a stored case's inputs differ from ``spec``'s: None if its sidecar's ``input_hash``
    is :func:`input_hash` of ``spec``, else the differing parameters
    (:func:`format_differences` of its recorded ``spec``; ``"input_hash differs"`` if no
    recorded parameter differs)."""
    if meta.get("input_hash") == input_hash(spec):
        return None
    theirs = meta.get("spec") if isinstance(meta.get("spec"), dict) else {}
    diffs = parameter_differences(theirs, spec_record(spec))
    return format_differences(diffs) or "input_hash differs"


# --------------------------------------------------------------------------- cases


def write_case(
    directory: str | os.PathLike[str],
    spec: CaseSpec,
    result: CaseResult,
    *,
    wall_time_s: float | None = None,
    prov: Mapping[str, Any] | None = None,
) -> CaseFiles:
    """Write one finished case: the CSV first, then the JSON sidecar, both atomically.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory (must exist).
    spec : CaseSpec
        The inputs of the case.
    result : CaseResult
        The FE result; ``result.table`` must hold :data:`REQUIRED_COLUMNS` and
        ``result.status`` must be one of :data:`VALID_STATUSES`.
    wall_time_s : float, optional
        Wall time of the solve in s (default ``result.info["wall_time_s"]`` if present).
    prov : mapping, optional
        Output of :func:`provenance` (computed here if omitted).

    Returns
    -------
    CaseFiles
        Paths written.

    Raises
    ------
    ValueError
        If the result lacks required columns or has an unknown status (nothing is written).
    grasprom.fe.atomicio.AtomicWriteError
        An :class:`OSError` naming the file if a write fails (e.g. disk full); nothing of the
        case is left behind.
    """
    stem = spec_stem(spec)
    files = case_files(directory, stem)
    _check_result(stem, result)
    info = dict(result.info or {})
    if wall_time_s is None:
        wall_time_s = info.get("wall_time_s")
    if prov is None:
        prov = provenance()

    csv_bytes = result.table.to_csv(index=False, lineterminator="\n").encode()
    meta = _sidecar(spec, result, files, csv_bytes, wall_time_s, prov)
    atomic_write_bytes(files.csv, csv_bytes)
    try:
        atomic_write_json(files.json, meta)
    except BaseException:
        files.csv.unlink(missing_ok=True)  # a CSV without its sidecar is no finished case
        raise
    return files


def _check_result(stem: str, result: CaseResult) -> None:
    """ValueError if the result table lacks :data:`REQUIRED_COLUMNS` or its status is unknown."""
    missing = [c for c in REQUIRED_COLUMNS if c not in result.table.columns]
    if missing:
        raise ValueError(f"case {stem}: result table lacks required columns {missing}")
    if result.status not in VALID_STATUSES:
        raise ValueError(
            f"case {stem}: status {result.status!r} is not one of {list(VALID_STATUSES)}"
        )


def model_keys(spec: Any) -> dict[str, Any]:
    """What a case sidecar records about its FE model.

    Returns
    -------
    dict
        ``model`` (``"2d"`` or ``"3d"``), ``contact``, ``friction`` (the Coulomb coefficient,
        0 unless ``contact`` is ``coulomb``), ``tube_length_mm`` (None in 2D: the plane-strain
        ring is infinitely long) and ``ends`` (None in 2D).
    """
    mu = float(getattr(spec, "friction", 0.0))
    if hasattr(spec, "tube_length_mm"):
        return {
            "model": "3d",
            "contact": spec.contact,
            "friction": mu,
            "tube_length_mm": spec.tube_length_mm,
            "ends": spec.ends,
        }
    return {
        "model": "2d",
        "contact": spec.contact,
        "friction": mu,
        "tube_length_mm": None,
        "ends": None,
    }


def _sidecar(
    spec: CaseSpec,
    result: CaseResult,
    files: CaseFiles,
    csv_bytes: bytes,
    wall_time_s: float | None,
    prov: Mapping[str, Any],
) -> dict[str, Any]:
    """The JSON sidecar of a case whose CSV holds ``csv_bytes`` (units in ``parameter_units``)."""
    table = result.table
    info = dict(result.info or {})
    spec_d = spec_record(spec)
    return {
        "schema_version": SCHEMA_VERSION,
        "stem": spec_stem(spec),
        "material": spec.material,
        "thickness_mm": spec.thickness_mm,
        "diameter_mm": spec.diameter_mm,
        "jaw_length_mm": spec.jaw_length_mm,
        "closed_gap_mm": spec.closed_gap_mm,
        "force_cap_N": spec.force_cap_N,
        **model_keys(spec),
        "status": result.status,
        "n_steps": int(len(table)),
        "last_gap_mm": _finite_or_none(table["gap_mm"].min()) if len(table) else None,
        "max_force_N": _finite_or_none(table["force_N"].max()) if len(table) else None,
        "material_constants": info.get("material_constants"),
        "mesh": spec_d["mesh"],
        "solver": spec_d["solver"],
        "spec": spec_d,
        "fe_info": info,
        "wall_time_s": wall_time_s,
        "input_hash": input_hash(spec),
        "csv_file": files.csv.name,
        "csv_sha256": sha256_bytes(csv_bytes),
        "columns": list(map(str, table.columns)),
        "units": {str(c): COLUMN_UNITS.get(str(c)) for c in table.columns},
        "parameter_units": SPEC_UNITS,
        "versions": dict(prov.get("versions", {})),
        "git_revision": prov.get("git_revision"),
        "git_dirty": prov.get("git_dirty"),
        "written_at": now_iso(),
    }


def _finite_or_none(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def own_wall_time_s(fe_info: Mapping[str, Any]) -> float:
    """Wall time (s) of a case's own FE run, from a sidecar's ``fe_info``: its
    ``own_wall_time_s`` where a band selection added a companion run (its ``wall_time_s`` is
    then the total; :mod:`grasprom.fe.bandselect`), else its ``wall_time_s``; NaN if neither.
    """
    return float(fe_info.get("own_wall_time_s", fe_info.get("wall_time_s", math.nan)))


def read_json_file(path: str | os.PathLike[str], what: str = "JSON") -> Any:
    """Parse a UTF-8 JSON file, whatever the locale.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What it is, for the message (e.g. ``"manifest JSON"``).

    Returns
    -------
    object
        The parsed JSON.

    Raises
    ------
    CorruptCaseError
        Naming the file if it cannot be read, is not UTF-8 (with the byte offset) or does
        not parse.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise CorruptCaseError(path, f"cannot read {what} ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CorruptCaseError(
            path, f"{what} is not valid UTF-8 (byte 0x{data[exc.start]:02x} at offset {exc.start})"
        ) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise CorruptCaseError(path, f"{what} does not parse ({exc})") from None


_REQUIRED_META = (
    "schema_version",
    "material",
    "thickness_mm",
    "status",
    "input_hash",
    "csv_sha256",
)


def read_case(path: str | os.PathLike[str]) -> LoadedCase:
    """Read and validate one case.

    Parameters
    ----------
    path : str or os.PathLike
        The ``<stem>.json`` sidecar, the ``<stem>.csv`` or the stem path without suffix.

    Returns
    -------
    LoadedCase

    Raises
    ------
    CorruptCaseError
        If the JSON is missing or does not parse, lacks required keys, the CSV is missing,
        its SHA-256 differs from the sidecar's ``csv_sha256``, or it lacks required columns.
    """
    p = Path(path)
    if p.suffix in (".json", ".csv"):
        p = p.with_suffix("")
    files = case_files(p.parent, p.name)
    if not files.json.is_file():
        raise CorruptCaseError(files.json, "sidecar JSON not found")
    meta = read_json_file(files.json, "JSON")
    if not isinstance(meta, dict):
        raise CorruptCaseError(files.json, "JSON is not an object")
    missing = [k for k in _REQUIRED_META if k not in meta]
    if missing:
        raise CorruptCaseError(files.json, f"missing keys {missing}")
    if meta["schema_version"] != SCHEMA_VERSION:
        raise CorruptCaseError(
            files.json,
            f"schema_version {meta['schema_version']!r}, this grasprom reads {SCHEMA_VERSION}",
        )
    if meta["status"] not in VALID_STATUSES:
        raise CorruptCaseError(files.json, f"unknown status {meta['status']!r}")
    if not files.csv.is_file():
        raise CorruptCaseError(files.csv, "CSV file not found (its JSON sidecar exists)")
    try:
        data = files.csv.read_bytes()
    except OSError as exc:
        raise CorruptCaseError(files.csv, f"cannot read ({exc})") from None
    digest = sha256_bytes(data)
    if digest != meta["csv_sha256"]:
        raise CorruptCaseError(
            files.csv,
            f"sha256 {digest[:12]}... does not match csv_sha256 "
            f"{str(meta['csv_sha256'])[:12]}... recorded in {files.json.name}",
        )
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CorruptCaseError(
            files.csv,
            f"CSV is not valid UTF-8 (byte 0x{data[exc.start]:02x} at offset {exc.start})",
        ) from None
    try:
        import io

        table = pd.read_csv(io.BytesIO(data))
    except Exception as exc:  # noqa: BLE001 - any parse failure is corruption
        raise CorruptCaseError(files.csv, f"CSV does not parse ({exc})") from None
    missing_cols = [c for c in REQUIRED_COLUMNS if c not in table.columns]
    if missing_cols:
        raise CorruptCaseError(files.csv, f"missing required columns {missing_cols}")
    return LoadedCase(meta=meta, table=table, files=files)


def case_json_paths(directory: str | os.PathLike[str]) -> list[Path]:
    """Sidecar JSON files of the cases in ``directory`` (excludes the manifest), sorted."""
    d = Path(directory)
    return sorted(
        p for p in d.glob("*.json") if p.name != MANIFEST_NAME and not p.name.startswith(".")
    )


def load_sweep(directory: str | os.PathLike[str]) -> pd.DataFrame:
    """Load every finished case of a sweep directory into one long DataFrame.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory (e.g. ``fe_data/default``).

    Returns
    -------
    pandas.DataFrame
        Columns ``material``, ``thickness_mm`` (mm), ``status``, then the case CSV columns
        (units in :data:`COLUMN_UNITS`); rows sorted by material, thickness and load step.

    Raises
    ------
    FileNotFoundError
        If ``directory`` does not exist.
    CorruptCaseError
        If any case fails validation (see :func:`read_case`).
    """
    d = Path(directory)
    if not d.is_dir():
        raise FileNotFoundError(f"sweep directory {d} does not exist")
    frames = []
    for jp in case_json_paths(d):
        case = read_case(jp)
        t = case.table.copy()
        t.insert(0, "status", case.meta["status"])
        t.insert(0, "thickness_mm", float(case.meta["thickness_mm"]))
        t.insert(0, "material", str(case.meta["material"]))
        frames.append(t)
    if not frames:
        return pd.DataFrame(columns=["material", "thickness_mm", "status", *REQUIRED_COLUMNS])
    df = pd.concat(frames, ignore_index=True)
    return df.sort_values(["material", "thickness_mm"], kind="stable").reset_index(drop=True)


def write_error(directory: str | os.PathLike[str], stem: str, message: str, tb: str) -> Path:
    """Atomically write ``<stem>.error.txt`` recording a failed case.

    Returns
    -------
    pathlib.Path
        The error file.
    """
    path = Path(directory) / f"{stem}{ERROR_SUFFIX}"
    text = f"case: {stem}\ntime: {now_iso()}\nerror: {message}\n\n{tb}"
    atomic_write_bytes(path, text.encode())
    return path


# --------------------------------------------------------------------------- manifest


def sweep_parameters(spec: CaseSpec) -> dict[str, Any]:
    """The parameters a sweep shares across its cases: :func:`spec_record` minus the grid axes."""
    d = spec_record(spec)
    d.pop("material")
    d.pop("thickness_mm")
    return d


def case_parameters(meta: Mapping[str, Any]) -> dict[str, Any] | None:
    """The sweep parameters a case sidecar records (its ``spec`` minus the grid axes).

    Returns
    -------
    dict or None
        Comparable with a manifest's ``parameters`` (see :func:`sweep_parameters`); None if
        the sidecar has no ``spec``.
    """
    spec = meta.get("spec")
    if not isinstance(spec, Mapping):
        return None
    return {k: v for k, v in spec.items() if k not in ("material", "thickness_mm")}


def parameter_differences(
    expected: Mapping[str, Any], actual: Mapping[str, Any], prefix: str = ""
) -> list[tuple[str, Any, Any]]:
    """The keys where two parameter dicts differ, nested dicts compared key by key.

    Parameters
    ----------
    expected, actual : mapping
        E.g. a manifest's ``parameters`` and :func:`case_parameters` of a sidecar.
    prefix : str
        Prepended to the keys (dotted path of nested keys).

    Returns
    -------
    list of (str, object, object)
        ``(dotted key, expected value, actual value)``, sorted; a missing key has the value
        ``"<missing>"``. Values are compared by their canonical JSON (1 == 1.0).
    """
    out: list[tuple[str, Any, Any]] = []
    for k in sorted(set(expected) | set(actual), key=str):
        a, b = expected.get(k, "<missing>"), actual.get(k, "<missing>")
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out.extend(parameter_differences(a, b, f"{prefix}{k}."))
        elif canonical_json(a) != canonical_json(b) and not _same_number(a, b):
            out.append((f"{prefix}{k}", a, b))
    return out


def _same_number(a: Any, b: Any) -> bool:
    """True for two equal numbers (ints and floats alike, not booleans)."""
    nums = (int, float)
    return (
        isinstance(a, nums)
        and isinstance(b, nums)
        and not isinstance(a, bool)
        and not isinstance(b, bool)
        and float(a) == float(b)
    )


def format_differences(diffs: Sequence[tuple[str, Any, Any]], limit: int = 3) -> str:
    """``"key: expected != actual"`` for the first ``limit`` differences, comma-separated."""
    text = ", ".join(f"{k}: {a!r} != {b!r}" for k, a, b in diffs[:limit])
    return text + (f" (and {len(diffs) - limit} more)" if len(diffs) > limit else "")


def read_manifest(directory: str | os.PathLike[str]) -> dict | None:
    """Read ``sweep.json`` of a sweep directory.

    Returns
    -------
    dict or None
        The manifest, or None if there is none.

    Raises
    ------
    CorruptCaseError
        If the manifest exists but does not parse.
    """
    path = Path(directory) / MANIFEST_NAME
    if not path.is_file():
        return None
    m = read_json_file(path, "manifest JSON")
    if not isinstance(m, dict) or "cases" not in m or "parameters" not in m:
        raise CorruptCaseError(path, "manifest lacks 'cases' or 'parameters'")
    return m


def write_manifest(
    directory: str | os.PathLike[str],
    specs: Sequence[CaseSpec],
    *,
    last_run: Mapping[str, Any] | None = None,
) -> dict:
    """Create or update ``sweep.json``, merging with an existing manifest.

    The manifest holds ``schema_version``, ``grasprom_version``, ``created`` and ``updated``
    (UTC ISO 8601), ``grid`` (sorted ``materials`` and ``thickness_mm`` over all cases),
    ``parameters`` (shared case inputs, see :func:`sweep_parameters`), ``cases`` (a list of
    ``{"stem", "material", "thickness_mm", "input_hash"}``), ``units`` and, after a run,
    ``last_run``.

    Parameters
    ----------
    directory : str or os.PathLike
        Sweep directory (must exist).
    specs : sequence of CaseSpec
        Cases of this run; all must share :func:`sweep_parameters`.
    last_run : mapping, optional
        Summary of the latest run to record.

    Returns
    -------
    dict
        The manifest written.

    Raises
    ------
    ValueError
        If the specs' shared parameters differ from each other or from the existing manifest.
    """
    d = Path(directory)
    if not specs:
        raise ValueError("write_manifest: no cases")
    params = sweep_parameters(specs[0])
    old = read_manifest(d)
    _check_manifest_parameters(d, specs, params, old)
    cases: dict[str, dict[str, Any]] = {}
    if old is not None:
        cases.update({c["stem"]: c for c in old["cases"]})
    for s in specs:
        stem = spec_stem(s)
        cases[stem] = {
            "stem": stem,
            "material": s.material,
            "thickness_mm": s.thickness_mm,
            "input_hash": input_hash(s),
        }
    case_list = sorted(cases.values(), key=lambda c: (c["material"], c["thickness_mm"]))
    now = now_iso()
    manifest: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "grasprom_version": __version__,
        "created": old.get("created", now) if old else now,
        "updated": now,
        "grid": {
            "materials": sorted({c["material"] for c in case_list}),
            "thickness_mm": sorted({c["thickness_mm"] for c in case_list}),
        },
        "parameters": params,
        "cases": case_list,
        "units": {**SPEC_UNITS, **{f"csv:{k}": v for k, v in COLUMN_UNITS.items()}},
    }
    if last_run is not None:
        manifest["last_run"] = dict(last_run)
    elif old is not None and "last_run" in old:
        manifest["last_run"] = old["last_run"]
    atomic_write_json(d / MANIFEST_NAME, manifest)
    return manifest


def _check_manifest_parameters(
    d: Path, specs: Sequence[CaseSpec], params: dict[str, Any], old: dict | None
) -> None:
    """ValueError if the specs do not share ``params`` or the manifest ``old`` records others."""
    for s in specs[1:]:
        if sweep_parameters(s) != params:
            raise ValueError(
                "all cases of one sweep must share diameter, jaw length, gap, "
                "force cap, mesh and solver settings"
            )
    if old is not None and canonical_json(old["parameters"]) != canonical_json(params):
        diffs = parameter_differences(old["parameters"], params)
        raise ValueError(
            f"{d / MANIFEST_NAME} records different sweep parameters "
            f"({format_differences(diffs) or 'layout'}; sweep.json != this run); "
            "use another --out"
        )


def known_stems(directory: str | os.PathLike[str]) -> list[str]:
    """Stems of all cases a directory knows of: manifest, sidecars and error files."""
    d = Path(directory)
    stems: set[str] = set()
    try:
        m = read_manifest(d)
    except CorruptCaseError:
        m = None
    if m is not None:
        stems.update(c["stem"] for c in m["cases"])
    stems.update(p.stem for p in case_json_paths(d))
    stems.update(p.name[: -len(ERROR_SUFFIX)] for p in d.glob(f"*{ERROR_SUFFIX}"))
    return sorted(stems, key=lambda s: parse_stem(s) or (s, 0.0))
