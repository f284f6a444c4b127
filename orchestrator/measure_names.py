"""The names of the measures :mod:`orchestrator.compare.measures` computes, in its table's order; a
module outside that package (whose ``__init__`` loads the analysis stack) so that the command line
can offer them without importing it."""

MEASURES = ("profiles", "shearband", "displacements", "d2min", "clusters", "coordination", "fabric", "rdf",
            "friction", "macro")
