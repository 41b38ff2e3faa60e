"""pyclpt against Mitsuba 3: :mod:`.mitsuba_agreement` (images scene by scene), and Mitsuba's sides of the
evaluations (``mitsuba_gradients``, ``mitsuba_visibility``, ``mitsuba_shadow``), run by the Python of Mitsuba's own
environment (they import only mitsuba, drjit and ``bench.report.mitsuba_driver``). The timing comparison is
``pyclpt bench --versus mitsuba`` (:mod:`bench.report.versus`)."""
