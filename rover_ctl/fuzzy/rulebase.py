"""A Mamdani rule base compiled to a consequent table over the grid of input-set combinations.

Inference: a rule's strength is the AND (``min`` or ``product``) of its antecedent memberships;
an output set's strength is the max over the rules concluding it; the defuzzifier
(``rover_ctl.fuzzy.defuzzify``) turns set strengths into a crisp value. When no rule fires for an
output, the output is its variable's ``default`` (never NaN, never an exception).

An input a rule does not mention means "any set of that input": the rule stands for one cell per
set of that input (the expansion a complete rule table would spell out), so its strength there is
``AND(its antecedents, membership of that input's set)``. The rule base therefore compiles to
one table ``consequent[output][cell]`` over the cells ``(set of input 1, ..., set of input n)``,
with ``-1`` where no rule concludes that output. Two rules concluding different sets of one output
in the same cell are read as a decision list: the earlier rule decides that cell (the later one
still decides the cells it alone covers), so a general rule can follow specific exceptions.
Refused when the rule base is built: two rules with the same conditions and different
conclusions (a conflict), and a rule that decides no cell at all (shadowed by earlier rules).

Compiled evaluation uses sparsity: at any point of a universe made of overlapping
piecewise-linear sets only a few sets (``Variable.max_active()``, 2 for a usual partition) are
non-zero, so a row fires at most ``prod(max_active)`` cells (64 for the paper's six inputs)
instead of all 972; strengths of those cells are an outer AND of per-input vectors, their
consequents a table look-up, and the per-set max a scatter-max (``np.maximum.at``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from rover_ctl.fuzzy.defuzzify import DEFUZZIFIERS
from rover_ctl.fuzzy.membership import Variable

ROWS_PER_CHUNK = 32768
"""Rows evaluated at once in batch: small enough for the ~2 kB of temporaries per row (paper's
base) to stay in the CPU cache."""


MAX_BLOCK_TABLE = 1 << 22
"""Largest blocks x corners table compiled for the chained batch path (the paper's is 8,192);
bigger rule bases take the general path."""


class RuleBaseError(ValueError):
    """A rule base that cannot be used; the message names the file and the rule."""


@dataclass(frozen=True)
class Rule:
    """One rule: a set index per input (None = any) and per output (None = no conclusion)."""

    antecedent: tuple[int | None, ...]
    consequent: tuple[int | None, ...]
    text: str
    where: str
    """Where it was read, e.g. ``paper.toml rule 12``, for error messages."""


@dataclass
class RuleBase:
    name: str
    inputs: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    rules: tuple[Rule, ...]
    and_method: str = "min"
    defuzzifier: str = "area_centre"
    resolution: int = 1001
    """Samples across an output's range for the sampled defuzzifiers."""
    description: str = ""
    source: str = ""
    warnings: list[str] = field(default_factory=list)
    """Coverage report: cells where an output has no rule (filled when built)."""

    def __post_init__(self) -> None:
        if self.and_method not in ("min", "product"):
            raise RuleBaseError(f"{self.source}: unknown 'and' method {self.and_method!r} (known: min, product)")
        if self.defuzzifier not in DEFUZZIFIERS:
            raise RuleBaseError(
                f"{self.source}: unknown defuzzifier {self.defuzzifier!r} (known: {', '.join(DEFUZZIFIERS)})"
            )
        self._defuzz = DEFUZZIFIERS[self.defuzzifier]
        self._and = np.minimum if self.and_method == "min" else np.multiply
        self._sizes = [len(v.sets) for v in self.inputs]
        # Row-major strides: cell = sum(set_index_i * stride_i).
        self._strides = [int(np.prod(self._sizes[i + 1 :], dtype=np.int64)) for i in range(len(self.inputs))]
        n_cells = int(np.prod(self._sizes, dtype=np.int64))
        self._table = np.full((len(self.outputs), n_cells), -1, dtype=np.int16)
        self._cell_rule = np.full(n_cells, -1, dtype=np.int32)
        owner = np.full((len(self.outputs), n_cells), -1, dtype=np.int32)
        first_with: dict[tuple[int | None, ...], int] = {}
        for index, rule in enumerate(self.rules):
            earlier = first_with.setdefault(rule.antecedent, index)
            if earlier != index:
                other = self.rules[earlier]
                for o, (k, j) in enumerate(zip(rule.consequent, other.consequent)):
                    if k is not None and j is not None and k != j:
                        raise RuleBaseError(
                            f"{rule.where}: conflicts with {other.where}: same conditions, {self.outputs[o].name} "
                            f"is {self.outputs[o].sets[k].name} vs {self.outputs[o].sets[j].name}"
                        )
            cells = self._cells_of(rule.antecedent)
            self._cell_rule[cells] = np.where(self._cell_rule[cells] < 0, index, self._cell_rule[cells])
            decides = False
            for o, k in enumerate(rule.consequent):
                if k is None:
                    continue
                fresh = cells[self._table[o, cells] < 0]
                self._table[o, fresh] = k
                owner[o, fresh] = index
                decides = decides or fresh.size > 0
            if not decides and earlier == index:
                shadows = sorted({int(owner[o, c]) for o in range(len(self.outputs)) for c in cells if owner[o, c] >= 0})
                raise RuleBaseError(
                    f"{rule.where}: never applies: every combination it covers is decided by earlier rules "
                    f"({', '.join(self.rules[i].where.rsplit(' ', 1)[-1] for i in shadows[:8])})"
                )
        for o, output in enumerate(self.outputs):
            missing = np.flatnonzero(self._table[o] < 0)
            if missing.size:
                examples = "; ".join(self.describe_cell(int(c)) for c in missing[:3])
                more = f" and {missing.size - 3} more" if missing.size > 3 else ""
                self.warnings.append(
                    f"{self.source}: {missing.size} input combination(s) have no rule for {output.name}: "
                    f"{examples}{more} (the output falls back on the other rules, or on {output.default:g})"
                )
        self._active = [v.max_active() for v in self.inputs]
        self._table_lists = [row.tolist() for row in self._table]
        self._n_sets_out = [len(v.sets) for v in self.outputs]
        # Consequent per cell with "no rule" sent to a sink column past the output's sets.
        self._slot_tables = [np.where(t < 0, n, t).astype(np.intp) for t, n in zip(self._table, self._n_sets_out)]
        self._chain_peaks = [v.chain_peaks() for v in self.inputs]
        pairs = [len(v.sets) if v.period is not None else len(v.sets) - 1 for v in self.inputs]
        block_table = int(np.prod(pairs, dtype=np.int64)) * 2 ** len(self.inputs)
        self._chained = all(p is not None for p in self._chain_peaks) and block_table <= MAX_BLOCK_TABLE
        if self._chained:
            self._compile_blocks()
        points = [np.array([s.points for s in v.sets]) for v in self.outputs]
        # Paper defuzzifier terms per output set: bottom + core, slopes, peak (pure-Python path).
        self._area_terms = [
            [(float(d - a + c - b), float((b - a) + (d - c)), float((b + c) / 2.0)) for a, b, c, d in p] for p in points
        ]

    def _compile_blocks(self) -> None:
        """For chain inputs: per block, which corners conclude which output set (batch path).

        A block is one choice of neighbouring-set pair per input; a corner picks the lower or the
        upper set of each pair (bit i of the corner number, the first input most significant).
        """
        pairs = [len(v.sets) if v.period is not None else len(v.sets) - 1 for v in self.inputs]
        self._block_strides = [int(np.prod(pairs[i + 1 :], dtype=np.int64)) for i in range(len(pairs))]
        m = len(self.inputs)
        blocks = np.arange(int(np.prod(pairs, dtype=np.int64)))
        corners = np.arange(2**m)
        cell = np.zeros((blocks.size, corners.size), dtype=np.intp)
        for i, variable in enumerate(self.inputs):
            lower = (blocks // self._block_strides[i]) % pairs[i]
            bit = (corners >> (m - 1 - i)) & 1
            cell += ((lower[:, None] + bit[None, :]) % len(variable.sets)) * self._strides[i]
        # Per output and block: the corners sorted by the set they conclude, where each set's run
        # starts, and which sets those are (corners concluding nothing are left out).
        self._block_plan = []
        for table in self._table:
            consequent = table[cell]
            plan = []
            for row in consequent:
                concluding = np.flatnonzero(row >= 0)
                ordered = concluding[np.argsort(row[concluding], kind="stable")]
                sets, starts = np.unique(row[ordered], return_index=True)
                plan.append((ordered, starts, sets))
            self._block_plan.append(plan)
        self._n_blocks = blocks.size

    # ----- structure -------------------------------------------------------------------------
    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.inputs)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.outputs)

    def _cells_of(self, antecedent: tuple[int | None, ...]) -> np.ndarray:
        cells = np.zeros(1, dtype=np.int64)
        for i, choice in enumerate(antecedent):
            options = np.arange(self._sizes[i]) if choice is None else np.array([choice])
            cells = (cells[:, None] + options[None, :] * self._strides[i]).ravel()
        return cells

    def describe_cell(self, cell: int) -> str:
        parts = []
        for variable, stride, size in zip(self.inputs, self._strides, self._sizes):
            parts.append(f"{variable.name}={variable.sets[(cell // stride) % size].name}")
        return ", ".join(parts)

    # ----- batch -----------------------------------------------------------------------------
    def evaluate(self, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Crisp outputs for arrays of inputs (broadcast together); a dict of output arrays."""
        missing = [n for n in self.input_names if n not in inputs]
        if missing:
            raise RuleBaseError(f"{self.name}: missing input(s) {', '.join(missing)}")
        arrays = np.broadcast_arrays(*[np.asarray(inputs[n], dtype=np.float64) for n in self.input_names])
        shape = arrays[0].shape
        flat = [a.ravel() for a in arrays]
        rows = flat[0].size
        result = {v.name: np.empty(rows) for v in self.outputs}
        for start in range(0, rows, ROWS_PER_CHUNK):
            chunk = [a[start : start + ROWS_PER_CHUNK] for a in flat]
            for output, mu in zip(self.outputs, self.set_strengths(chunk)):
                crisp = self._defuzz(mu, output, self.resolution)
                result[output.name][start : start + ROWS_PER_CHUNK] = np.where(np.isnan(crisp), output.default, crisp)
        return {name: values.reshape(shape) for name, values in result.items()}

    def set_strengths(self, columns: list[np.ndarray]) -> list[np.ndarray]:
        """Per output, the strength of each of its sets: arrays of shape (rows, sets).

        Arrays are laid out (combinations, rows) so that every numpy loop runs along the rows.
        """
        if self._chained:
            return self._set_strengths_chained(columns)
        rows = columns[0].size
        row_index = np.arange(rows)
        strength = np.ones((1, rows), dtype=np.float32)
        cell = np.zeros((1, rows), dtype=np.intp)
        for variable, x, active, stride in zip(self.inputs, columns, self._active, self._strides):
            mu = variable.memberships(x).T.astype(np.float32)  # sets x rows
            if active < mu.shape[0]:
                # The `active` strongest sets: the only ones that can be non-zero.
                picked_index, picked_mu = [], []
                for _ in range(active):
                    best = mu.argmax(axis=0)
                    picked_index.append(best)
                    picked_mu.append(mu[best, row_index])
                    mu[best, row_index] = -1.0
                index, mu = np.array(picked_index), np.array(picked_mu)
            else:
                index = np.broadcast_to(np.arange(mu.shape[0])[:, None], mu.shape)
            strength = self._and(strength[:, None, :], mu[None, :, :]).reshape(-1, rows)
            cell = (cell[:, None, :] + (index * stride)[None, :, :]).reshape(-1, rows)
        result = []
        for table, n_sets in zip(self._slot_tables, self._n_sets_out):
            slots = table[cell]
            slots += row_index * (n_sets + 1)
            aggregate = np.zeros(rows * (n_sets + 1), dtype=np.float32)
            np.maximum.at(aggregate, slots.ravel(), strength.ravel())
            result.append(aggregate.reshape(rows, n_sets + 1)[:, :n_sets].astype(np.float64))
        return result

    def _set_strengths_chained(self, columns: list[np.ndarray]) -> list[np.ndarray]:
        """``set_strengths`` for chain inputs: rows sorted by block, then per block a fixed
        corner -> set map, so each set's strength is a max over a fixed run of corners."""
        rows = columns[0].size
        lowers = [v.pair_index(x, p) for v, x, p in zip(self.inputs, columns, self._chain_peaks)]
        block = np.zeros(rows, dtype=np.intp)
        for lower, stride in zip(lowers, self._block_strides):
            block += lower * stride
        order = np.argsort(block, kind="stable")
        bounds = np.searchsorted(block[order], np.arange(self._n_blocks + 1))
        row_index = np.arange(rows)
        strength = np.ones((1, rows), dtype=np.float32)
        for variable, x, lower, peaks in zip(self.inputs, columns, lowers, self._chain_peaks):
            x, lower = x[order], lower[order]
            mu = variable.membership_rows(x).astype(np.float32).ravel()  # sets x rows, flattened
            upper = (lower + 1) % len(peaks)
            pair = np.stack((mu[lower * rows + row_index], mu[upper * rows + row_index]))
            strength = self._and(strength[:, None, :], pair[None, :, :]).reshape(-1, rows)
        result = []
        for plan, n_sets in zip(self._block_plan, self._n_sets_out):
            aggregate = np.zeros((n_sets, rows), dtype=np.float32)  # in block order
            for b in np.flatnonzero(bounds[1:] > bounds[:-1]):
                corners, starts, sets = plan[b]
                if corners.size:
                    begin, end = bounds[b], bounds[b + 1]
                    aggregate[sets, begin:end] = np.maximum.reduceat(strength[corners, begin:end], starts, axis=0)
            unsorted = np.empty((rows, n_sets))
            unsorted[order] = aggregate.T
            result.append(unsorted)
        return result

    # ----- single (control loop) ---------------------------------------------------------------
    def _fired_cells(self, values: Mapping[str, float]) -> list[tuple[int, float]]:
        """(cell, strength) of every cell with non-zero strength, in pure Python."""
        fired = [(0, 1.0)]
        use_min = self.and_method == "min"
        for variable, stride in zip(self.inputs, self._strides):
            try:
                x = float(values[variable.name])
            except KeyError:
                raise RuleBaseError(f"{self.name}: missing input {variable.name}") from None
            nonzero = [(j * stride, m) for j, m in enumerate(variable.memberships_one(x)) if m > 0.0]
            if use_min:
                fired = [(c + offset, s if s < m else m) for c, s in fired for offset, m in nonzero]
            else:
                fired = [(c + offset, s * m) for c, s in fired for offset, m in nonzero]
        return fired

    def evaluate_one(self, **values: float) -> dict[str, float]:
        """Crisp outputs for one set of inputs through the compiled pure-Python path."""
        fired = self._fired_cells(values)
        result = {}
        for o, output in enumerate(self.outputs):
            table = self._table_lists[o]
            mu = [0.0] * self._n_sets_out[o]
            for cell, s in fired:
                k = table[cell]
                if k >= 0 and s > mu[k]:
                    mu[k] = s
            if self.defuzzifier == "area_centre":
                total = moment = 0.0
                for m, (base, slopes, peak) in zip(mu, self._area_terms[o]):
                    if m > 0.0:
                        area = 0.5 * m * (base + (1.0 - m) * slopes)
                        total += area
                        moment += area * peak
                result[output.name] = moment / total if total > 0.0 else output.default
            else:
                crisp = float(self._defuzz(np.array([mu]), output, self.resolution)[0])
                result[output.name] = output.default if crisp != crisp else crisp
        return result

    def explain(self, **values: float) -> list[tuple[int, float, str]]:
        """Rules that fired for these inputs: (rule index, strength, rule text), strongest first.

        A rule's strength is the max over the cells it covers (one cell unless it leaves inputs
        open); a cell is credited to the first rule that covers it.
        """
        strengths: dict[int, float] = {}
        for cell, s in self._fired_cells(values):
            rule = int(self._cell_rule[cell])
            if rule >= 0 and s > strengths.get(rule, 0.0):
                strengths[rule] = s
        ranked = sorted(strengths.items(), key=lambda item: (-item[1], item[0]))
        return [(index, s, self.rules[index].text) for index, s in ranked]
