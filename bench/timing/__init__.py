"""Measurements to re-run on a new machine or after a change: frame times (:mod:`.frame_time`), devices side by
side (:mod:`.devices`), scene loads (:mod:`.load_times`), BVH builds (:mod:`.bvh_build`), per-stage throughput and
PoCL's vectorizer remarks (:mod:`.stage_profile`, :mod:`.vectorizer_remarks`), the viewer's overhead
(:mod:`.viewer_overhead`)."""
