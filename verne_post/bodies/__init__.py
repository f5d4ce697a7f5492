"""Bodies of the machine and the setup: shapes, distances, the sampling bound."""
