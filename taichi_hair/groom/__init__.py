"""Grooming (Daviet 2023 Sec. 5.3): the interactive session, guides and skinning, groom generators.

* :mod:`.session`: :class:`GroomingSession`, edits inside a live quasistatic simulation; it composes the
  modules below, which never call back into it (they get what they need as arguments and return results);
* :mod:`.config`: :class:`GroomingConfig`, the action and parameter names, the checks of the actions' arguments;
* :mod:`.selection`: brush, pick-ray and strand hits, and how they combine with a selection;
* :mod:`.edits`: trim, length and curl edits as pure functions on the groom's NumPy arrays;
* :mod:`.history`: undo/redo snapshots, the session log (write, parse, replay checks), autosave names;
* :mod:`.comb`: a comb stroke (path steps, the sweep of the comb collider, the combed strands);
* :mod:`.simulation`: :class:`GuideSimulation`, the guides' Model, solver, State and skinning, updated in place;
* :mod:`.guides`: guide selection (10 %, farthest-point sampling), :class:`SkinningConfig`;
* :mod:`.binding`: binding of every strand to its guides (and the proxy vertices of a session);
* :mod:`.skinning`: linear-blend skinning of the full groom by the guides, interpolation error;
* :mod:`.generators`: procedural grooms (scalp sampling, straight / wavy / curly strands).
"""
