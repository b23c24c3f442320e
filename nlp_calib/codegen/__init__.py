"""Code-generation layer: C compiled from the problem's Functions, for the compiled backend and for export."""
