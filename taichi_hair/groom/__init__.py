"""Grooming (Daviet 2023 Sec. 5.3): the interactive session, guides and skinning, groom generators.

* :mod:`.session`: :class:`GroomingSession`, edits inside a live quasistatic simulation;
* :mod:`.skinning`: guide selection (10 %), binding and linear-blend skinning of the full groom;
* :mod:`.generators`: procedural grooms (scalp sampling, straight / wavy / curly strands).
"""
