"""A campaign's results on disk: a Parquet dataset written as runs finish.

Layout of a campaign directory::

    DIR/campaign.json        the checked spec (canonical form), to resume only the same campaign
    DIR/results/*.parquet    the rows: one file per finished run (``run-*``), merged into
                             part files (``part-*``) every few hundred runs and at the end
    DIR/logs/<run_id>/       each run's log.csv and summary.json (keep = "logs")

Every file appears whole or not at all (written under a temporary name, then renamed), so a
crash, a lost worker or Ctrl-C loses at most the runs in flight. A run written twice (a
merge interrupted between writing the part file and removing the files it merged, or a
failed run run again on resume) is read once: the rows that finished last.
"""

from __future__ import annotations

import json
import uuid
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from biso_cosim.output import atomic_output

__all__ = ["ResultStore", "StoreError", "read_results"]

RESULTS = "results"
SPEC_FILE = "campaign.json"
LOGS = "logs"


class StoreError(ValueError):
    """An output directory that cannot hold this campaign (one line, naming the directory)."""


def _atomic_write(path: Path, write) -> None:
    """``write(temporary_path)``, then rename it to ``path``: readers never see a partial file."""
    with atomic_output(path, keep_suffix=False) as temporary:
        write(temporary)


def _table(rows: list[dict[str, Any]]) -> pa.Table:
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    return pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in rows])


def read_results(directory: str | Path) -> pa.Table:
    """Every row of a results directory, each (run, estimator) once, in the order runs finished."""
    files = sorted(Path(directory).glob("*.parquet"))
    if not files:
        return pa.table({})
    table = pa.concat_tables([pq.read_table(f) for f in files], promote_options="permissive")
    frame = table.to_pandas()
    frame = frame.sort_values("finished_at", kind="stable").drop_duplicates(["run_id", "estimator"], keep="last")
    return pa.Table.from_pandas(frame.reset_index(drop=True), preserve_index=False)


class ResultStore:
    """The campaign directory: spec, rows and logs (see the module docstring)."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)
        self.results = self.directory / RESULTS
        self.logs = self.directory / LOGS

    # ---------------------------------------------------------------- opening
    def check(self, canonical_spec: dict, resume: bool) -> None:
        """Refuse, before any run, a directory that cannot be written or holds another campaign
        (or this one, without ``resume``); makes the directory, writes nothing in it."""
        where = str(self.directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise StoreError(f"--out {where!r} exists and is not a directory")
        try:
            self.results.mkdir(parents=True, exist_ok=True)
            probe = self.results / f".probe.{uuid.uuid4().hex[:8]}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as exc:
            raise StoreError(f"--out {where!r} is not writable: {exc.strerror or exc}") from None
        spec_file = self.directory / SPEC_FILE
        if spec_file.exists():
            stored = json.loads(spec_file.read_text())
            if not resume:
                raise StoreError(f"--out {where!r} already holds a campaign ({stored.get('name')!r}); pass --resume "
                                 f"to complete it, or choose another directory")
            if stored != canonical_spec:
                field = next((k for k in sorted(set(stored) | set(canonical_spec))
                              if stored.get(k) != canonical_spec.get(k)), "?")
                raise StoreError(f"--resume: the spec differs from the campaign in {where!r} (field {field!r}); "
                                 f"resume with the same spec, or choose another directory")
        elif any(self.results.glob("*.parquet")):
            raise StoreError(f"--out {where!r} holds results but no {SPEC_FILE}; choose another directory")

    def open(self, canonical_spec: dict, resume: bool) -> None:
        """``check``, then record the campaign's spec (new directory) or reopen it (``resume``)."""
        self.check(canonical_spec, resume)
        spec_file = self.directory / SPEC_FILE
        if not spec_file.exists():
            text = json.dumps(canonical_spec, indent=2, sort_keys=True) + "\n"
            _atomic_write(spec_file, lambda p: p.write_text(text))

    # ---------------------------------------------------------------- rows
    def finished_run_ids(self) -> set[str]:
        """Runs whose rows are there with a result (failed runs are run again on resume)."""
        table = read_results(self.results)
        if table.num_rows == 0:
            return set()
        frame = table.select(["run_id", "status"]).to_pandas()
        return set(frame.loc[frame["status"] != "failed", "run_id"])

    def append(self, rows: list[dict[str, Any]]) -> Path:
        """Write one finished run's rows as a file of their own."""
        path = self.results / f"run-{rows[0]['run_id']}-{uuid.uuid4().hex[:8]}.parquet"
        table = _table(rows)
        _atomic_write(path, lambda p: pq.write_table(table, p))
        return path

    def compact(self) -> None:
        """Merge the per-run files written since the last merge into one part file (earlier
        parts stay as they are, so that merging as a campaign goes costs each row once)."""
        files = sorted(self.results.glob("run-*.parquet"))
        if len(files) < 2:
            return
        merged = pa.concat_tables([pq.read_table(f) for f in files], promote_options="permissive")
        path = self.results / f"part-{uuid.uuid4().hex[:12]}.parquet"
        _atomic_write(path, lambda p: pq.write_table(merged, p))
        for f in files:
            f.unlink()

    def table(self) -> pa.Table:
        return read_results(self.results)

    def spec(self) -> dict:
        spec_file = self.directory / SPEC_FILE
        if not spec_file.exists():
            raise StoreError(f"{str(self.directory)!r} holds no campaign ({SPEC_FILE} missing)")
        return json.loads(spec_file.read_text())

