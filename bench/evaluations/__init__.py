"""How good a feature is, against exact answers, converged references or Mitsuba 3: gradients
(:mod:`.gradients`), the boundary term of visibility (:mod:`.visibility_gradients`, :mod:`.edge_sampling`),
inverse rendering (:mod:`.inverse_rendering`, :mod:`.inverse_pose`, :mod:`.inverse_shape`: the examples of
docs/differentiable.md) and pixel filters (:mod:`.rfilter_noise`)."""
