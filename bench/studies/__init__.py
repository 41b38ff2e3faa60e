"""Studies that answered their question, kept runnable to measure again: each module's first lines state the
question, the answer with its figure, and the doc that quotes it (docs/bvh.md, docs/wavefront.md,
docs/accumulation.md)."""
