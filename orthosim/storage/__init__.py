"""Bytes on disk: atomic writes, checksummed cache entries and the source digests that key caches.

`atomic` (write beside, then rename), `cacheentry` (every cache's entries: format, key and SHA-256,
verified on read), `sourcedigest` (cache keys that change with the code), `checksums` (a file's
SHA-256: is this the file a result was made from), `shipped` (cache entries shipped in the package for
the shipped cases, read on a miss in the user's cache), `numpytally` (the seconds earlier runs spent on
the numpy forms of the compiled kernels, so that short runs too compile once it pays).
"""
