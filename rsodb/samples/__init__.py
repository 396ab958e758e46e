"""Data the project generates itself: the bundled sample passes (`generate`, ``python -m
rsodb.samples``) and synthetic observation files for benchmarks and tests (`synthetic`)."""

from rsodb.samples.generate import SAMPLES, SampleSpec, SpinTruth, generate
from rsodb.samples.synthetic import synthetic_pass, synthetic_tle, write_synthetic_corpus

__all__ = [
    "SAMPLES",
    "SampleSpec",
    "SpinTruth",
    "generate",
    "synthetic_pass",
    "synthetic_tle",
    "write_synthetic_corpus",
]
