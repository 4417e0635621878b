"""Ingest: log readers (chosen by content), database loading, vectorized decoding, signal maps."""
