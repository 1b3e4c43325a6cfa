"""``python -m bench soak``: the soak of bench/soak.py (hostile frames against a running daemon)."""

from bench.soak import run

__all__ = ["run"]
