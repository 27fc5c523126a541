"""Jobs: the SQLite job store and the worker processes that run them."""
