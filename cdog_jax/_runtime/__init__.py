"""The package's private runtime: padded shapes and their ladder, memory estimates, the
compilation cache and stored programs, progress reports, and names loaded on first use.
Nothing here is part of the public API."""
