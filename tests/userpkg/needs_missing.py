"""A module whose own import fails, as when a dependency is not installed."""

import motorlab_no_such_dependency  # noqa: F401
