"""Scenes: TOML files that declare a study, parsed (:mod:`~toolkit.scenes.spec`), built into
objects (:mod:`~toolkit.scenes.build`), run (:mod:`~toolkit.scenes.study`) and written out
(:mod:`~toolkit.scenes.report`)."""
