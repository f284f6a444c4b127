"""Scenes: each module defines one experiment behind :class:`orchestrator.scenes.base.Scene`
(its case section, the case terms it realises, its derived numbers, required engine features,
control names with units, the neutral series its decks write, and ``post``).

Scenes are found through the registry (:func:`orchestrator.registry.get_scene`, entry-point group
``orchestrator.scenes`` in pyproject.toml); adding one is one module plus one template per engine
(docs/architecture.md).
"""
