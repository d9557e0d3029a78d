"""What a benchmark leaves: its result as JSON where ``--json`` names a file, written first (a long run's figures
survive a broken pipe), then its table on stdout."""
from __future__ import annotations

import json
from pathlib import Path


def emit(result: dict, table: str, json_path: str | None) -> int:
    """Write ``result`` to ``json_path`` (when given), print ``table``; 0, the tool's exit status."""
    if json_path:
        Path(json_path).write_text(json.dumps(result, indent=1))
    print(table)
    return 0
