"""The error of unusable image-regression input, apart from the comparison so that the label and
explanation modules can raise it without importing the comparison that imports them."""

from __future__ import annotations

from orthosim.errors import OrthosimError


class ImageInputError(OrthosimError):
    """A golden or candidate image (or its sidecar or label files) is missing, unreadable, truncated, not a PNG,
    of another size, or a tolerance names nothing."""
