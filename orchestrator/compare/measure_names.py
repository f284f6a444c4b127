"""The names of the measures :mod:`.measures` computes, in its table's order; a module of its own so
that the command line can offer them without importing the analysis stack."""

MEASURES = ("profiles", "shearband", "displacements", "d2min", "clusters", "coordination", "fabric", "rdf",
            "friction", "macro")
