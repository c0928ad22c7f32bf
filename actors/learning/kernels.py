"""The learner's arithmetic per step, compiled (paper §4: Eqs. 2-9): one agent's decide() is a few calls into this
module instead of some forty numpy calls, each of which cost more than the arithmetic it did.

Bit for bit what the numpy learner computed, so that runs stay what they were:
- sums are added in numpy's order: pairwise_sum is numpy's pairwise summation, and the dot products of Eqs. 2 and 9
  are numpy's own BLAS calls with numpy's arguments (blas.py);
- the exponentials of Eqs. 3 and 8 are not here: the exp compiled code calls (the C library's) and numpy's (SVML on
  AVX-512 machines) differ in the last bit for ~5 % of arguments, so the learner calls numpy's exp between kernels;
- top-k ties: the k kept sets are taken in numpy's argpartition order, which is by value when the values differ;
  kept_sets() declines when two of them are equal and the caller asks numpy (fuzzy.py).

All compiled functions live in this one file: numba's cache notices a change of the file a function is defined in,
not of the files its callees come from.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from .blas import COL_MAJOR, ROW_MAJOR, TRANS, ddot, dgemv

# -- sums in numpy's order --------------------------------------------------------------------------------------------


@njit(cache=True)
def _block_sum(a, lo, n):
    """sum(a[lo:lo + n]), n <= 128, as numpy adds it: below 8 one by one, else in 8 running sums."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    end = lo + n - n % 8
    for i in range(lo + 8, end, 8):
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(end, lo + n):
        res += a[i]
    return res


@njit(cache=True)
def pairwise_sum(a, lo, n):
    """sum(a[lo:lo + n]) added as numpy adds a contiguous float64 array (its pairwise_sum): blocks of up to 128
    (_block_sum), longer runs as the sum of their two halves, cut at a multiple of 8. numpy recurses; this walks the
    same tree with a stack: a recursive function loaded from numba's cache crashed the process (numba 0.68)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    runs = np.empty((64, 3), dtype=np.int64)  # open runs: start, length, how many of its halves are summed
    sums = np.empty(64)  # sums of finished runs not yet added to their sibling
    runs[0, 0], runs[0, 1], runs[0, 2] = lo, n, 0
    depth, n_sums = 1, 0
    while depth:
        start, length, done = runs[depth - 1, 0], runs[depth - 1, 1], runs[depth - 1, 2]
        half = length // 2
        half -= half % 8
        if length <= 128:
            sums[n_sums] = _block_sum(a, start, length)
            n_sums += 1
            depth -= 1
        elif done == 2:  # both halves summed: first + second, as numpy's recursion returns it
            sums[n_sums - 2] = sums[n_sums - 2] + sums[n_sums - 1]
            n_sums -= 1
            depth -= 1
        else:
            runs[depth - 1, 2] = done + 1
            runs[depth, 0] = start if done == 0 else start + half
            runs[depth, 1] = half if done == 0 else length - half
            runs[depth, 2] = 0
            depth += 1
    return sums[0]


@njit(cache=True)
def total(a):
    """a.sum(): numpy starts a reduction at 0.0 and adds the pairwise sum of the whole array."""
    return 0.0 + pairwise_sum(a, 0, a.size)


# -- Eqs. 3-4: memberships and sparse rule activation -----------------------------------------------------------------


@njit(cache=True)
def exponents(x, lo_hi_sigma, bounds, grid, out):
    """out = sigma_v (b - x_v) at every real boundary b of every variable v (x_v clipped to [lo_v, hi_v], the exponent
    capped at 700): what Eq. 3's e^(-sigma (x - b)) exponentiates. Variable v's n_sets[v] - 1 boundaries (grid[0])
    follow variable v - 1's."""
    lo, hi, sigma = lo_hi_sigma[0], lo_hi_sigma[1], lo_hi_sigma[2]
    pos = 0
    for v in range(x.size):
        xv = x[v]
        if xv < lo[v]:  # outside the range: clip, memberships stay valid (NaN stays NaN, as numpy's clipping)
            xv = lo[v]
        if xv > hi[v]:
            xv = hi[v]
        for _ in range(grid[0, v] - 1):
            arg = sigma[v] * (bounds[pos] - xv)
            out[pos] = 700.0 if arg > 700.0 else arg
            pos += 1


@njit(cache=True)
def memberships(e, n_sets, L_pad, mu):
    """Eq. 3 from e = exponents() exponentiated: L_b = 1 / (1 + rho e^(-sigma x)) at each boundary, set j =
    L_{b_{j-1}} - L_{b_j} with L_{b_{-1}} = 1 and L_{b_{m-1}} = 0, a partition of unity.

    mu is (n_vars, max m): a variable with fewer sets has padded boundaries (b = +inf, L = L_pad) and padded sets
    (-1, never kept), as FuzzyPartition.memberships() lays them out."""
    width = mu.shape[1]
    pos = 0
    for v in range(mu.shape[0]):
        m = n_sets[v]
        upper = 1.0  # L_{b_{j-1}}
        for j in range(width):
            if j < m - 1:
                lower = 1.0 / (1.0 + e[pos])  # Eq. 3
                pos += 1
            elif j < width - 1:
                lower = L_pad
            else:
                lower = 0.0
            mu[v, j] = upper - lower if j < m else -1.0
            upper = lower


@njit(cache=True)
def kept_sets(mu, n_sets, top):
    """top[v] = the top_k sets of variable v, largest membership first: numpy's (-mu).argpartition(top_k - 1)
    order when the values differ. False when two of a variable's top_k + 1 largest are equal (or NaN): numpy's
    order of ties is its sorting network's, and the caller asks numpy."""
    n_vars, width = mu.shape
    k = top.shape[1]
    if k == width:  # every set kept, in order (no argpartition)
        for v in range(n_vars):
            for c in range(k):
                top[v, c] = c
        return True
    largest = np.empty(k + 1)  # the k + 1 largest memberships so far, largest first, and their sets
    sets = np.empty(k + 1, dtype=np.int64)
    for v in range(n_vars):
        for c in range(k + 1):
            largest[c] = -np.inf
        for j in range(n_sets[v]):
            x = mu[v, j]
            if x != x:
                return False
            if x > largest[k]:  # insert; an equal value goes after the one already there
                c = k
                while c > 0 and x > largest[c - 1]:
                    largest[c], sets[c] = largest[c - 1], sets[c - 1]
                    c -= 1
                largest[c], sets[c] = x, j
        for c in range(k):
            if largest[c] == largest[c + 1]:  # a tie among the k + 1 largest
                return False
            top[v, c] = sets[c]
    return True


@njit(cache=True)
def fire(mu, top, strides, rules, O):  # noqa: E741
    """Eq. 4 over the top_k^n fired rules, built variable by variable: rule i keeps set top[v, c_v] of each variable
    v, c = the digits of i in base top_k (variable 0 first, as itertools.product); O^i = prod_v mu_v (left to
    right); rules[i] its row-major index in the full grid."""
    n_vars, k = top.shape
    for c in range(k):
        rules[c] = top[0, c] * strides[0]
        O[c] = mu[0, top[0, c]]
    n = k
    for v in range(1, n_vars):
        for i in range(n - 1, -1, -1):  # in place: rule i becomes rules i k .. i k + k - 1
            rule, o = rules[i], O[i]
            for c in range(k - 1, -1, -1):
                j = top[v, c]
                rules[i * k + c] = rule + j * strides[v]
                O[i * k + c] = o * mu[v, j]  # Eq. 4
        n *= k


@njit(cache=True)
def activate(e, grid, L_pad, top_k, rules, O):  # noqa: E741
    """Eqs. 3-4 from the exponentials e: memberships, the kept sets, the fired rules and O. grid: (n_sets, strides)
    per variable. False when the kept sets tie: the caller takes numpy's top and calls fire()."""
    mu = np.empty((grid.shape[1], grid[0].max()))
    memberships(e, grid[0], L_pad, mu)
    top = np.empty((grid.shape[1], top_k), dtype=np.int64)
    if not kept_sets(mu, grid[0], top):
        return False
    fire(mu, top, grid[1], rules, O)
    return True


# -- phi storage: rule -> phi row -------------------------------------------------------------------------------------
# An insertion-ordered hash map in arrays (qlearning.RuleIndex): table[s] = (key, value) or (-1, -1) when empty, a
# power of two of slots with at most half in use, linear probing; the keys and values again in insertion order
# (entries[0], entries[1]), size[0] of them.


@njit(cache=True)
def _slot(key, mask):
    h = key * -7046029254386353131  # Fibonacci hashing (2^64 / golden ratio, wrapping), high bits folded down
    return (h ^ (h >> 32)) & mask


@njit(cache=True)
def map_get(table, key):
    """The value of key (>= 0), -1 when absent."""
    mask = table.shape[0] - 1
    s = _slot(key, mask)
    while True:
        k = table[s, 0]
        if k == key:
            return table[s, 1]
        if k < 0:
            return -1
        s = (s + 1) & mask


@njit(cache=True)
def map_set(table, entries, size, key, value):
    """map[key] = value; a new key becomes entry size[0] (the caller made room)."""
    mask = table.shape[0] - 1
    s = _slot(key, mask)
    while table[s, 0] >= 0 and table[s, 0] != key:
        s = (s + 1) & mask
    if table[s, 0] == key:  # a new value for a key already there
        for e in range(size[0]):
            if entries[0, e] == key:
                entries[1, e] = value
    else:
        entries[0, size[0]], entries[1, size[0]] = key, value
        size[0] += 1
    table[s, 0], table[s, 1] = key, value


@njit(cache=True)
def map_rehash(table, entries, n):
    """table for the first n entries (distinct keys), after it was replaced by a larger one."""
    mask = table.shape[0] - 1
    for s in range(table.shape[0]):
        table[s, 0] = table[s, 1] = -1
    for e in range(n):
        s = _slot(entries[0, e], mask)
        while table[s, 0] >= 0:
            s = (s + 1) & mask
        table[s, 0], table[s, 1] = entries[0, e], entries[1, e]


@njit(cache=True)
def lookup(table, rules, rows):
    """rows[i] = the phi row of rules[i], -1 for a rule never updated."""
    for i in range(rules.size):
        rows[i] = map_get(table, rules[i])


# -- Eqs. 2, 5, 6: Q and its TD update --------------------------------------------------------------------------------


@intrinsic
def _at(typingctx, a, start):
    """The address of element `start` (counted flat) of the C-contiguous array a: what BLAS takes."""

    def codegen(context, builder, signature, args):
        return builder.gep(context.make_array(signature.args[0])(context, builder, args[0]).data, [args[1]])

    return types.CPointer(a.dtype)(a, types.intp), codegen


@njit(cache=True)
def q_values(phi, rows, w, out, A, wk):
    """Q(s, .) = sum_i w_i phi^i over the rules with a row (Eq. 2; a rule never updated has phi = 0), w = O / sum O:
    numpy's w[known] @ phi[rows[known]], i.e. BLAS dgemv on the gathered rows (A, wk: room for them)."""
    n_actions = phi.shape[1]
    known = 0
    for r in rows:
        if r >= 0:
            known += 1
    for a in range(n_actions):
        out[a] = 0.0
    if known == 0:
        return
    c = 0
    for i in range(rows.size):
        r = rows[i]
        if r >= 0:
            for a in range(n_actions):
                A[c, a] = phi[r, a]
            wk[c] = w[i]
            c += 1
    dgemv(ROW_MAJOR, TRANS, known, n_actions, 1.0, _at(A, 0), n_actions, _at(wk, 0), 1, 0.0, _at(out, 0), 1)  # Eq. 2


@njit(cache=True)
def q_value(phi, rows, w, action, column):
    """Q(s, a) = sum_i w_i phi^i[a] (Eq. 2) over rows that all exist: numpy's w @ phi[rows, a] (BLAS ddot; column:
    room for phi[rows, a])."""
    for i in range(rows.size):
        column[i] = phi[rows[i], action]
    return 0.0 + ddot(rows.size, _at(w, 0), 1, _at(column, 0), 1)


@njit(cache=True)
def update(phi, rows, w, action, delta):
    """phi^i[a] += delta w_i (Eq. 6): w_i = O^i / sum O = dQ(s, a) / dphi^i; the rows are distinct."""
    for i in range(rows.size):
        phi[rows[i], action] += delta * w[i]


# -- Eqs. 7-9: joint action selection ---------------------------------------------------------------------------------


@njit(cache=True)
def probabilities(counts, P):
    """P^i(alpha_k^j) = C^i(alpha_k^j) / sum_b C^i(b^j) (Eq. 7)."""
    for j in range(counts.shape[0]):
        s = total(counts[j])
        for b in range(counts.shape[1]):
            P[j, b] = counts[j, b] / s


@njit(cache=True)
def expected_values(q, P, E, room):
    """E(alpha_i) = sum_{alpha_-i} Q(s, alpha_i u alpha_-i) prod_j P(alpha_j) (Eq. 9): Q(s, .) as (n,) * (1 + n_visible)
    contracted with P from the last visible agent on, as numpy's E @ P[j]: a BLAS dgemv per n x n block. room: at
    least 1.5 q.size floats, for Q and the partial contractions, one after the other."""
    n = E.size
    for i in range(q.size):
        room[i] = q[i]
    at, size = 0, q.size  # Q contracted so far: size floats of room from at
    for j in range(P.shape[0] - 1, -1, -1):
        for b in range(size // (n * n)):
            block, to = _at(room, at + b * n * n), _at(room, at + size + b * n)
            dgemv(COL_MAJOR, TRANS, n, n, 1.0, block, n, _at(P, j * n), 1, 0.0, to, 1)
        at, size = at + size, size // n
    for a in range(n):
        E[a] = room[at + a]


@njit(cache=True)
def greatest(a):
    """a.max(), NaN if any is (numpy's)."""
    m = a[0]
    for x in a[1:]:
        if x > m or x != x:
            m = x
        if m != m:
            break
    return m


# -- one step of Algorithm 1 ------------------------------------------------------------------------------------------
TIED = -1  # decide(): the kept sets of s(t) tie


# decide() takes 19 arguments, not 20: CPython 3.11 makes a 20-item tuple anew at every call (its free list takes them
# back but hands out only shorter ones) and counts it towards the next garbage collection without uncounting it;
# a call with 20 (the dispatcher makes two such tuples) brought a full collection of the ~110,000 objects numba
# keeps, ~50 ms, every ~35,000 calls.


@njit(cache=True)
def decide(
    e, grid, L_pad, top_k, activated, fired, w, now, p_joint, td, reward, lr, gamma, T,
    phi, table, entries, size, selection,
):  # fmt: skip
    """Learner.decide() up to the choice of a(t): returns 0 when done; TIED, before anything changed, when the kept
    sets of s(t) tie (the caller fires s(t) with numpy's order of them and calls again, activated); or the rows phi
    must hold first (the caller grows it and calls again, activated: nothing else has changed).

    e: Eq. 3's exponentials for s(t) (grid, L_pad, top_k: FuzzyPartition's). fired[i] = (rules, phi rows)
    of s(t) (i = now) and s(t-1) (the other), w[i] their O / sum O; selection: the fictitious-play counts (Eq. 7),
    P (Eq. 7), E (Eq. 9) and z (Eq. 8), in Learner's layout. With td, the TD update (Eqs. 5-6) of s(t-1) and its
    joint action p_joint with s(t) as s'; then P, E and z = (E - max E) / T, the exponent of the Boltzmann policy
    (Eq. 8) that a(t) is chosen from."""
    rules, rows, w_now = fired[now, 0], fired[now, 1], w[now]
    p_rules, p_rows, p_w = fired[1 - now, 0], fired[1 - now, 1], w[1 - now]
    nv = (selection.shape[0] - 2) // 2  # n_visible
    counts, P, E, z = selection[:nv], selection[nv : 2 * nv], selection[2 * nv], selection[2 * nv + 1]
    if not activated and not activate(e, grid, L_pad, top_k, rules, w_now):  # Eqs. 3-4: rules, O in w
        return TIED
    if td:  # room first: rules of s(t-1) never updated get phi rows below
        new = 0
        for r in p_rows:
            if r < 0:
                new += 1
        need = size[0] + new
        if new and (need > phi.shape[0] or need > entries.shape[1]):
            return need
    n_actions = phi.shape[1]
    q_now = np.empty(n_actions)
    # room for the gathered phi rows and weights of Eq. 2, and for Eq. 9's partial contractions
    A, wk, room = np.empty((rules.size, n_actions)), np.empty(rules.size), np.empty(2 * n_actions)
    norm = total(w_now)
    for i in range(w_now.size):
        w_now[i] = w_now[i] / norm  # O^i / sum_i O^i: the weight of rule i in Eq. 2 and its gradient in Eq. 6
    lookup(table, rules, rows)
    probabilities(counts, P)  # Eq. 7
    q_values(phi, rows, w_now, q_now, A, wk)  # Q(s(t), .), Eq. 2

    if td:  # (a) TD update of the previous transition with s(t) as s' (Eqs. 5-6)
        for i in range(p_rows.size):  # rules never updated get phi = 0 rows, in rule order
            if p_rows[i] < 0:
                p_rows[i] = size[0]
                map_set(table, entries, size, p_rules[i], p_rows[i])
        q_sa = q_value(phi, p_rows, p_w, p_joint, wk)  # Q(s(t-1), a(t-1)), Eq. 2
        # Eq. 5's max over what this agent can choose: max_a E(s', a) (Eq. 9), not over joint actions
        expected_values(q_now, P, E, room)
        delta = lr * (reward + gamma * greatest(E) - q_sa)  # Eq. 5
        update(phi, p_rows, p_w, p_joint, delta)  # Eq. 6
        for i in range(rows.size):
            if rows[i] < 0:  # s(t) may share rules just created for s(t-1)
                rows[i] = map_get(table, rules[i])
        q_values(phi, rows, w_now, q_now, A, wk)

    # (b) JASM: E (Eq. 9) and the Boltzmann exponent (Eq. 8); the caller exponentiates with numpy
    expected_values(q_now, P, E, room)
    best = greatest(E)  # subtracted for numerical stability
    for a in range(E.size):
        z[a] = (E[a] - best) / T
    return 0
