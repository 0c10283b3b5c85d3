"""Image file reading with one-line errors naming the file."""
import os

import imageio.v3 as iio
import numpy as np

from renerf_jax.errors import DataError

IMAGE_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.PNG', '.JPG', '.JPEG')


def list_images(folder):
  """Sorted image files of a folder; DataError if the folder is missing or empty."""
  if not os.path.isdir(folder):
    raise DataError(f'image folder not found: {folder}')
  files = sorted(f for f in os.listdir(folder) if f.endswith(IMAGE_EXTENSIONS))
  if not files:
    raise DataError(f'no images (.png/.jpg) in {folder}')
  return [os.path.join(folder, f) for f in files]


def read_image(path, keep_alpha=False):
  """Reads an 8/16-bit image as float32 in [0, 1], shape [H, W, 3] (or 4 with keep_alpha).

  Greyscale photos (and greyscale + alpha) are converted on purpose, not refused: the grey
  is replicated to 3 channels; an alpha channel is dropped unless keep_alpha (then a
  missing alpha is filled with 1), so one folder may mix greyscale, RGB and RGBA files.
  A missing, empty, truncated or undecodable file, or non-finite pixels, is a DataError
  naming the file.
  """
  if not os.path.isfile(path):
    raise DataError(f'image file not found: {path}')
  if os.path.getsize(path) == 0:
    raise DataError(f'image file is empty (0 bytes): {path}')
  try:
    img = np.asarray(iio.imread(path))
  except Exception as e:  # pylint: disable=broad-except
    raise DataError(f'cannot read image {path}: {type(e).__name__}: '
                    f'{str(e).splitlines()[0] if str(e) else "corrupt file"}') from None
  if img.dtype == np.uint8:
    img = img.astype(np.float32) / 255.
  elif img.dtype == np.uint16:
    img = img.astype(np.float32) / 65535.
  else:
    img = img.astype(np.float32)
  if img.ndim == 2:
    img = img[..., None]
  if img.ndim != 3 or img.shape[-1] not in (1, 2, 3, 4):
    raise DataError(f'unsupported image shape {img.shape} in {path}')
  if img.shape[-1] in (1, 2):  # Gray or gray + alpha.
    gray = np.repeat(img[..., :1], 3, axis=-1)
    img = np.concatenate([gray, img[..., 1:]], -1) if img.shape[-1] == 2 else gray
  if not np.all(np.isfinite(img)):
    raise DataError(f'non-finite pixel values in {path}')
  if keep_alpha:
    if img.shape[-1] == 3:
      img = np.concatenate([img, np.ones_like(img[..., :1])], -1)
    return img
  return img[..., :3]


def read_images(paths, keep_alpha=False):
  """Reads images that must all have the same size; [N, H, W, C] float32."""
  imgs = []
  for p in paths:
    img = read_image(p, keep_alpha)
    if imgs and img.shape[:2] != imgs[0].shape[:2]:
      raise DataError(f'image {p} is {img.shape[1]}x{img.shape[0]} but {paths[0]} is '
                      f'{imgs[0].shape[1]}x{imgs[0].shape[0]}: all images must have one size')
    imgs.append(img)
  return np.stack(imgs, 0)
