"""The policies shipped with the package: one folder each, in the safe policy format."""

from __future__ import annotations

from pathlib import Path

MANIFEST = "policy.json"
"""The file that makes a folder a policy (`agents.policy_format`)."""
SHIPPED_DIR = Path(__file__).resolve().parent


def shipped_policies() -> list[str]:
    """Names of the policies shipped with the package."""
    return sorted(p.name for p in SHIPPED_DIR.iterdir() if (p / MANIFEST).is_file())
