"""CAN log ingest: readers, DBC loading, vectorised decoding, bus statistics, signal maps."""

from app.ingest._lazy_cantools import defer_cantools_tester

defer_cantools_tester()
