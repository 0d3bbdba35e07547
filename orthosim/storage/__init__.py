"""Bytes on disk: atomic writes and the source digests that key caches.

`atomic` (write beside, then rename), `sourcedigest` (cache keys that change with the code).
"""
