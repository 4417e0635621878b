"""Generators the tests and the benchmarks share: simulated truth drives and the BLF logs written from them."""
