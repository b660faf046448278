"""Scenes: :mod:`.file` (the TOML scene format: schema, animation, solver and groom set-up),
:mod:`.builtin` (the built-in scenes: hang, hairball, ...), :mod:`.variants` (parameter variants of a
scene for batch runs)."""
