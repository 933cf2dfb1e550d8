"""The built-in images ('builtin:NAME'): scikit-image's samples read from its data folder with imageio, the same
pixels as skimage.data's functions give, without importing skimage.data (0.3 s in every dataset worker)."""
import subprocess
import sys

import numpy as np
import pytest
import skimage.data

from udc_render.content.monitor_image import BUILTIN_IMAGES, builtin_image, read_code_values


@pytest.mark.parametrize("name", BUILTIN_IMAGES)
def test_a_builtin_image_has_skimage_datas_pixels(name):
    ours, theirs = builtin_image(name), getattr(skimage.data, name)()
    assert ours.dtype == theirs.dtype and np.array_equal(ours, theirs)


def test_reading_a_builtin_image_imports_neither_skimage_data_nor_skimage_io():
    code = ("import sys; from udc_render.content.monitor_image import read_code_values; "
            "a = read_code_values('builtin:coffee'); "
            "print(a.shape, [m for m in ('skimage.data', 'skimage.io') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "(400, 600, 3) []"
    assert read_code_values("builtin:coffee").shape == (400, 600, 3)
