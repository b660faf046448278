"""Scenes: :mod:`.file` (the TOML scene format: :class:`~.file.Scene`, :func:`~.file.load_scene`), read by
:mod:`.schema` (the table reader), :mod:`.setup` (groom, colliders, solver) and :mod:`.animation` (body
keyframes and presets); :mod:`.builtin` (the built-in scenes: hang, hairball, ...), :mod:`.variants`
(parameter variants of a scene for batch runs); :mod:`.checkpoint` (simulation checkpoints, exact resume)."""
