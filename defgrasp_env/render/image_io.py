"""Write RGB images to PNG (Pillow when installed, else a minimal zlib PNG writer)."""

from __future__ import annotations

import os
import pathlib
import struct
import zlib

import numpy as np


def png_bytes(image: np.ndarray, level: int = 6) -> bytes:
    """Encode an RGB uint8 [H, W, 3] image as PNG (8-bit truecolour, filter 0 on every row; zlib
    ``level``, 1 = fast)."""
    img = np.ascontiguousarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image must be uint8 with shape (H, W, 3), got {img.dtype} {img.shape}")
    h, w, _ = img.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), img.reshape(h, w * 3)], axis=1).tobytes()

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, level)) + chunk(b"IEND", b"")


def save_png(path, image: np.ndarray) -> pathlib.Path:
    """Save an RGB image uint8 [H, W, 3] (row 0 at the top) to path, atomically (tmp + rename).

    Returns the path written.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image must be uint8 with shape (H, W, 3), got {img.dtype} {img.shape}")
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        from PIL import Image
    except ImportError:
        tmp.write_bytes(png_bytes(img))
    else:
        Image.fromarray(np.ascontiguousarray(img)).save(tmp, format="PNG")
    os.replace(tmp, path)
    return path
