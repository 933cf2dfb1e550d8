"""The separable resampling matrices behind the panel's scaler and the analytic render."""
import numpy as np
import pytest
from skimage.transform import resize

from udc_render.content.resample import overlap_matrix, resample, resize_matrix


@pytest.mark.parametrize("shape_in,shape_out", [((37, 50), (160, 211)), ((7, 5), (20, 31)), ((9, 9), (9, 9))])
def test_enlarging_equals_skimage_linear_resize(shape_in, shape_out):
    img = np.random.default_rng(0).random((*shape_in, 3))
    want = resize(img, shape_out, order=1, anti_aliasing=False, preserve_range=True)
    got = resample(img.transpose(2, 0, 1), resize_matrix(shape_in[0], shape_out[0]),
                   resize_matrix(shape_in[1], shape_out[1])).transpose(1, 2, 0)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)


def test_shrinking_is_the_area_mean_and_keeps_the_mean():
    img = np.random.default_rng(1).random((1, 60, 90))
    got = resample(img, resize_matrix(60, 20), resize_matrix(90, 30))[0]
    np.testing.assert_allclose(got, img[0].reshape(20, 3, 30, 3).mean(axis=(1, 3)), atol=1e-14)  # whole factor 3
    odd = resample(img, resize_matrix(60, 23), resize_matrix(90, 41))[0]
    assert abs(odd.mean() - img.mean()) < 1e-12  # area weights conserve the integral


def test_overlap_matrix_integrates_cells_exactly():
    """Cells of width 0.37 px starting at −1.2: every pixel inside the covered span gets weight 1, the
    partly covered end pixels their covered length, pixels outside none."""
    edges = -1.2 + 0.37 * np.arange(31)  # covers [−1.2, 9.9]
    a = overlap_matrix(edges, 12).toarray()
    np.testing.assert_allclose(a.sum(axis=1), [1] * 9 + [0.9, 0, 0], atol=1e-12)
    np.testing.assert_allclose(a.sum(axis=0)[4:-1], 0.37, atol=1e-12)  # inner cells lie inside the grid
