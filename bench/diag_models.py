"""Shared pieces of the discover-vs-greedy diagnoses (``diag_tau_m_vs_greedy.py``, ``diag_qred_vs_greedy.py``).

A model is a list of columns on the case's rows; :class:`ModelTable` scores it the two ways those diagnoses compare:
the held-out bag's RMSE (what ``hdphm bench discover`` judges, with the paired z of its squared residuals against a
reference model) and the leave-one-block-out CV error of the fit blocks (what discover may choose on, with the
paired t of the per-block SSE drops, ``core._paired_t``). :meth:`ModelTable.greedy_replay` replays greedy's forward
selection (``greedy.greedy_discover``'s rule: the group that lowers the held-out SSE most, while it does by >= 2 %,
at most 6 groups) and reports every step. Diagnosis only: nothing here feeds an estimator.
"""

from __future__ import annotations

import numpy as np


class ModelTable:
    """Models scored on ``y`` (fit rows ``fit``, held-out rows ``ho``, fit blocks from ``blocks``), remembered by
    name so that later rows can be compared with them; ``width`` / ``digits``: the printed table's layout."""

    def __init__(self, y: np.ndarray, fit: np.ndarray, ho: np.ndarray, blocks: np.ndarray, *, width: int = 58,
                 digits: int = 5):
        self.y, self.fit, self.ho, self.blocks = y, fit, ho, blocks
        self.width, self.digits = width, digits
        self.rows: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def score(self, cols: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(held-out residuals, per-fit-block CV SSE) of the least-squares model on ``cols`` fitted on the fit rows."""
        from hd_ground.discovery.core import _lstsq
        from hd_twin.identify import BlockGram

        X = np.column_stack(cols)
        y, fit = self.y, self.fit
        r = (y - X @ _lstsq(X[fit], y[fit]))[self.ho]
        return r, BlockGram(X[fit], y[fit], self.blocks[fit]).cv_sse()

    def report(self, name: str, cols: list[np.ndarray], ref: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Score ``cols``, remember them as ``name`` and print one row (against the model ``ref`` when given)."""
        from hd_ground.discovery.core import _paired_t, chunked_paired_z

        r, cv = self.score(cols)
        self.rows[name] = (r, cv)
        n, dg = int(self.fit.sum()), self.digits
        s = f"{name:{self.width}s} held-out {np.sqrt(np.mean(r**2)):.{dg}f}  CV {np.sqrt(cv.sum() / n):.{dg}f}"
        if ref is not None:
            r0, cv0 = self.rows[ref]
            s += (f"  vs [{ref}]: CV SSE {(cv.sum() - cv0.sum()) / cv0.sum() * 100:+.2f}% (better in "
                  f"{np.mean(cv0 - cv > 0) * 100:.0f}% of blocks, t {_paired_t(cv0, cv):+.2f}), held-out paired z "
                  f"{chunked_paired_z(r**2 - r0**2, 20):+.2f}")
        print(s)
        return r, cv

    def greedy_replay(self, base: list[np.ndarray], base_name: str, groups: list, names: list[str]
                      ) -> tuple[list[np.ndarray], list[int], str]:
        """Greedy's forward selection from the model ``base_name`` (columns ``base``) over ``groups`` (their
        columns at index 3, as ``greedy._groups`` builds them), each step reported as ``greedy + names[i]``.
        Returns (the final columns, the chosen group indices, the final model's name)."""
        cols, used, prev, chosen = list(base), set(), base_name, []
        cur = float(np.sum(self.rows[base_name][0] ** 2))
        while len(chosen) < 6:
            trial = [(float(np.sum(self.score(cols + g[3])[0] ** 2)), i) for i, g in enumerate(groups) if i not in used]
            if not trial:
                break
            e, i = min(trial)
            if (cur - e) / cur < 0.02:
                break
            used.add(i)
            chosen.append(i)
            cols = cols + groups[i][3]
            name = "greedy + " + names[i]
            self.report(name, cols, prev)
            prev, cur = name, e
        return cols, chosen, prev

    def per_block(self, a: str, b: str, bag_of_block, fmt: str = "10.3f") -> None:
        """The per-fit-block CV SSE of the models ``a`` and ``b`` side by side (``bag_of_block(block)``: its bag)."""
        cva, cvb = self.rows[a][1], self.rows[b][1]
        print(f"per fit block CV SSE: [{a}] | [{b}], and the block's bag")
        for j, blk in enumerate(np.unique(self.blocks[self.fit])):
            print(f"   block {blk:3d} bag {bag_of_block(blk)}: {cva[j]:{fmt}} {cvb[j]:{fmt}}")
