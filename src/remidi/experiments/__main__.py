"""``python -m remidi.experiments``: write ``catalog.json`` from the experiment modules (after
adding or changing a built-in experiment's name, description, presets or algorithms)."""

import json

from remidi.experiments import CATALOG, catalog_entries

lines = [f" {json.dumps(name)}: {json.dumps(entry, ensure_ascii=False)}" for name, entry in catalog_entries().items()]
CATALOG.write_text("{\n" + ",\n".join(lines) + "\n}\n")
print(f"wrote {CATALOG}")
