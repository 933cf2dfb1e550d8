"""Experiments on the restorers: the face-detection study and the whole results loop (RESULTS.md)."""
