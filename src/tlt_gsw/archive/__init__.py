"""The GSW telemetry archive: SQLite recorder, schema migrations and read-only queries."""

from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.archive.schema import LATEST_VERSION, migrate

__all__ = ["LATEST_VERSION", "Recorder", "migrate"]
