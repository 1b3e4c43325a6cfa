"""Helpers shared by test areas (importable as ``support`` thanks to pytest's pythonpath)."""

from sitl.launch import free_port

__all__ = ["free_port"]
