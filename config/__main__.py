"""`python -m gngdt.config`: where gngdt's example configuration files are installed."""

from pathlib import Path

folder = Path(__file__).resolve().parent
print(folder)
for path in sorted(folder.rglob("*")):
    if path.is_file() and path.suffix in (".toml", ".json5"):
        print(f"  {path.relative_to(folder)}")
