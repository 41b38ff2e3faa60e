"""Scripts that write files the repository ships: the sky's data tables (:mod:`.make_sky_tables`) and the
pictures of docs/gallery.md (:mod:`.gallery`)."""
