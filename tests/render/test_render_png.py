"""The frame PNG encoder writes standard files any reader decodes to the exact pixels."""

import io

import numpy as np
import pytest
from PIL import Image

from orthosim_render.png import encode_png


@pytest.mark.parametrize("shape", [(7, 5), (7, 5, 3), (7, 5, 4), (480, 640, 3)])
def test_round_trip_is_lossless(shape):
    rng = np.random.default_rng(len(shape))
    image = rng.integers(0, 256, size=shape, dtype=np.uint8)
    image[2:4] = 200  # flat areas, as in real frames
    back = np.asarray(Image.open(io.BytesIO(encode_png(image))))
    assert back.shape == image.shape and np.array_equal(back, image)


def test_rejects_non_uint8():
    with pytest.raises(ValueError):
        encode_png(np.zeros((4, 4, 3), np.float32))
