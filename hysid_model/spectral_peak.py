"""A record's frequency from its displacement spectrum's largest peak (step 1 of :mod:`hysid_model.extraction`):
Hann window, zero padding to a power of 2, Gaussian interpolation of the peak; a long record's spectrum in the
memory of its padded length and half of it. :func:`hysid_model.steady.phase_slope_frequency` refines it.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hysid_model import steady
from hysid_model.errors import HysidInputError


@lru_cache(maxsize=8)
def _hann(n: int) -> np.ndarray:
    """``np.hanning(n)``, kept for records of the same length (a set's records mostly are)."""
    window = np.hanning(n)
    window.flags.writeable = False
    return window


def spectral_frequency(t: np.ndarray, x: np.ndarray, source: str) -> float:
    """Frequency of the largest displacement spectral peak (Hann window, zero padding to a power of 2, Gaussian interpolation).

    Accurate to a few percent of a bin (1 / record length); :func:`hysid_model.steady.phase_slope_frequency`
    refines it. A record of more than ``MAX_SAMPLES`` samples takes the memory of 1.5 copies of its padded length
    (:func:`_long_spectrum`), not 3 and a cached window.
    """
    n = t.size
    dt = (t[-1] - t[0]) / (n - 1)
    nfft = 1 << int(np.ceil(np.log2(n)))
    mag = np.abs(np.fft.rfft((x - x.mean()) * _hann(n), nfft)) if n <= steady.MAX_SAMPLES else _long_spectrum(x, nfft)
    first = int(np.ceil(nfft / (n - 1)))  # below one period per record there is no cycle to extract
    if first >= mag.size - 1 or not np.any(mag[first:] > 0):
        raise HysidInputError(f"{source}: the displacement does not oscillate")
    k = first + int(np.argmax(mag[first:-1]))
    peak = float(k)
    if k > first:
        a, b, c = np.log(mag[k - 1 : k + 2] + 1e-300)
        den = a - 2 * b + c
        peak = k + (0.5 * (a - c) / den if den < 0 else 0.0)
    return float(peak / (nfft * dt))


def _long_spectrum(x: np.ndarray, nfft: int) -> np.ndarray:
    """``|rfft((x - mean) * hanning, nfft)|`` of a long record, in the memory of the padded record and half of it:
    the windowed samples are written a piece at a time into one buffer, whose pairs (even, odd) are a complex
    sequence of length nfft / 2 transformed in place; the real transform's bins are unpacked from it a piece at a
    time (X_k = E_k + e^(-2 pi i k / nfft) O_k, E and O the transforms of the even and odd samples)."""
    from scipy import fft  # on first use: loading data stays quick to start

    n, half = x.size, nfft // 2
    buf = np.zeros(nfft)
    mean = x.mean()
    for a in range(0, n, steady.PIECE):
        b = min(a + steady.PIECE, n)
        np.subtract(x[a:b], mean, out=buf[a:b])
        buf[a:b] *= 0.5 + 0.5 * np.cos(np.pi * np.arange(1 - n + 2 * a, 1 - n + 2 * b, 2) / (n - 1))  # np.hanning's
    z = fft.fft(buf.view(np.complex128), overwrite_x=True)
    mag = np.empty(half + 1)
    for a in range(0, half + 1, steady.PIECE):
        k = np.arange(a, min(a + steady.PIECE, half + 1))
        zk, zc = z[k % half], np.conj(z[(half - k) % half])
        mag[k] = np.abs(0.5 * (zk + zc) - 0.5j * np.exp(-2j * np.pi * k / nfft) * (zk - zc))
    return mag
