"""A user's own env package, as the tests and the README's "your own env" section use it."""
