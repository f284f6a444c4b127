"""Runtime of the YADE decks: real Python modules copied beside the rendered script.

The adapter (``engines/yade.py`` ``render``) copies this package into the run directory as
``yade_runtime/``; the script (``templates/yade/*.py.j2``) holds only the derived numbers and the
wiring, and imports what it runs from here. The modules run under Debian's ``yade`` (its
``/usr/bin/python3.11`` and numpy 1.24) and never import ``orchestrator``.

Pure modules (numpy only, unit-tested with the project's Python, ``tests/test_yade_runtime.py``):

- :mod:`.mesh`      membrane mesh topology, pressure nodal forces, inner volume and area
- :mod:`.control`   servo and membrane-correction laws of the triaxial controller
- :mod:`.series`    atomic chunk/series writers, windowed means, series resume

Modules that need YADE (``import yade``): :mod:`.recorder`, :mod:`.monitors`, :mod:`.membrane`,
:mod:`.triaxial`.
"""
