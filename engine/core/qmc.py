"""Randomized quasi-Monte Carlo for the first dimensions of each path, in independent blocks.

A batch of n = B m paths draws its first `DIMENSIONS` uniforms (emission direction 2, first
free-flight distance 1, first bounce direction 2) from B blocks of m = 2^k Sobol points, each block
with its own random digital shift (Owen 1995; Dick & Pillichshammer 2010, sec. 12.1):

    u_ij = floor((x_j 2^32 XOR e_i) / 2^11) 2^-53,   x_j the j-th point (32-bit integers), e_i ~ U{0..2^64-1}^5:

the shift covers every bit, so each u_ij is uniform on the same 53-bit grid of [0, 1) as numpy's own
uniforms, every path is an unbiased sample, and the blocks are independent; the paths of one block
are not. Standard errors therefore treat a block as one sample (tally.py, the sample-sum moments): the B block sums are
independent and identically distributed, which is what the error formula needs.

Measured (benchmarks/path_cost.py --what qmc): variance per path of H0 about 0.5x (clear room) and
0.4x (smoky room, algorithm 5) of pseudo-random paths at m = 256.

The Sobol points are generated from the direction numbers of Joe & Kuo (2008, new-joe-kuo-6.21201,
dimensions 1-5); tests/engine/test_qmc.py checks them against `scipy.stats.qmc.Sobol`, which is not used
here because importing scipy.stats takes about 0.7 s, longer than a small job.
"""

from __future__ import annotations

from functools import cache

import numpy as np

#: uniforms per path drawn from the Sobol blocks: emission (2), first free flight (1), first bounce (2)
DIMENSIONS = 5
#: paths per block (a power of 2): blocks of 256 kept the variance gain of whole batches
#: (0.5x / 0.4x, against 0.8x / 0.4x with blocks of 64) while giving thousands of samples for errors
BLOCK = 256

#: fewest blocks per source device for a fixed-budget job to use them: its error bars then rest on at least
#: 64 independent samples (relative noise of a standard error ~1 / sqrt(2 x 63) = 9 %); smaller jobs draw
#: pseudo-random paths, each its own sample (a 4 096-path job would otherwise have 16)
MIN_BLOCKS = 64


def job_block(quasi_random: bool, paths_per_source: int | None) -> int:
    """KernelSettings.qmc_block of a job: BLOCK when quasi-random paths are asked and the job runs to an
    accuracy target (None) or has at least MIN_BLOCKS blocks per source device, else 1."""
    enough = paths_per_source is None or paths_per_source >= MIN_BLOCKS * BLOCK
    return BLOCK if quasi_random and enough else 1


#: Joe & Kuo (2008) primitive polynomials (degree s, coefficients a) and initial m_i, dimensions 2-5;
#: dimension 1 is the van der Corput sequence (m_i = 1)
_JOE_KUO = ((1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)), (3, 2, (1, 1, 1)))
_BITS = 32


def _direction_numbers(bits: int) -> np.ndarray:
    """(DIMENSIONS, bits) direction numbers v_i = m_i 2^(32 - i), i = 1..bits, as uint32.

    m_i = 2 a_1 m_(i-1) ^ 4 a_2 m_(i-2) ^ ... ^ 2^(s-1) a_(s-1) m_(i-s+1) ^ 2^s m_(i-s) ^ m_(i-s)
    (Bratley & Fox 1988; a_1 .. a_(s-1) the bits of a, most significant first)."""
    v = np.zeros((DIMENSIONS, bits), np.uint64)
    v[0] = [1 << (_BITS - i) for i in range(1, bits + 1)]
    for d, (s, a, m0) in enumerate(_JOE_KUO, start=1):
        m = list(m0)
        for i in range(s, bits):
            new = m[i - s] ^ (m[i - s] << s)
            for j in range(1, s):
                if (a >> (s - 1 - j)) & 1:
                    new ^= m[i - j] << j
            m.append(new)
        v[d] = [m[i] << (_BITS - 1 - i) for i in range(bits)]
    return v.astype(np.uint32)


@cache
def sobol_points(m: int) -> np.ndarray:
    """(m, DIMENSIONS) uint32: the first m = 2^k points of the Sobol sequence times 2^32 (the point set
    of scipy.stats.qmc.Sobol(d=5, scramble=False).random(m), possibly in another order)."""
    bits = int(m).bit_length() - 1
    if m < 1 or (1 << bits) != m:
        raise ValueError(f"a Sobol block has a power-of-2 number of points, not {m}")
    v = _direction_numbers(max(bits, 1))
    i = np.arange(m, dtype=np.uint64)
    x = np.zeros((m, DIMENSIONS), np.uint32)
    for b in range(bits):  # x_i = XOR of v_b over the set bits b of i
        x ^= np.where(((i >> np.uint64(b)) & np.uint64(1)).astype(bool)[:, None], v[:, b][None, :], np.uint32(0))
    x.flags.writeable = False
    return x


def block_size(n_paths: int, block: int) -> int:
    """Paths per independent sample of a batch: `block` when the batch is a whole number of blocks (and
    quasi-random blocks are on, block > 1), else 1 (pseudo-random paths, each its own sample)."""
    return block if block > 1 and n_paths >= block and n_paths % block == 0 else 1


def whole_blocks(n_paths: int, block: int) -> int:
    """A batch size for at most n_paths paths: rounded down to whole blocks when that loses at most 1/16 of
    the paths (n_paths >= 16 blocks), else n_paths itself (then pseudo-random unless already whole blocks:
    smaller batches cost more per path, e.g. maps whose many receivers cap the batch)."""
    return n_paths - n_paths % block if block > 1 and n_paths >= 16 * block else n_paths


def shifted_blocks(n_paths: int, block: int, rng: np.random.Generator) -> np.ndarray:
    """(DIMENSIONS, n_paths) uniforms in [0, 1): n_paths / block blocks of Sobol points, each block with
    its own random digital shift of all 64 bits (module docstring), kept to 53 bits as numpy's own
    uniforms are. Path j of the batch is point j % block of block j // block."""
    n_blocks = n_paths // block
    shift = rng.integers(0, np.iinfo(np.uint64).max, size=(DIMENSIONS, n_blocks, 1), dtype=np.uint64, endpoint=True)
    shift >>= np.uint64(11)  # (p ^ s) >> 11 = (p >> 11) ^ (s >> 11): the top 53 bits of the shifted point
    x = _points_53(block)[:, None, :] ^ shift  # (DIMENSIONS, blocks, block)
    return np.multiply(x.reshape(DIMENSIONS, n_paths), 2.0**-53)  # exact: 53-bit integers to float64


@cache
def _points_53(m: int) -> np.ndarray:
    """(DIMENSIONS, m) uint64: the top 53 bits of the Sobol points placed in the top 32 of 64 bits."""
    x = (sobol_points(m).T.astype(np.uint64) << np.uint64(32)) >> np.uint64(11)
    x.flags.writeable = False
    return x
