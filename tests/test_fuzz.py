"""Property-based robustness suite: bad and extreme inputs for every public function and reader.

Each example takes a valid call (``_fuzz_cases.SPECS``) or a valid file and breaks one argument
or one part of the file. The call runs in a ``_sandbox`` worker process, so a segfault, an
abort or a hang (per-call timeout) fails the example instead of killing pytest. Every outcome
must be one of:

* a ``ValueError`` or ``TypeError`` whose message names an argument of the call (for a reader:
  the file), or ``KeyboardInterrupt`` when a callback raised it;
* a result that satisfies the function's contract (finite, shapes, rows summing to 1, ...);
  inputs that are only re-typed or re-laid-out (float32, Fortran order, views, lists) must give
  a result.

Profiles (environment ``SKINRS_FUZZ``): ``ci`` (default, >= 2,000 cases, < 3 minutes) and
``long`` (``make fuzz``, >= 50,000 cases). Found examples are kept in ``tests/.hypothesis``
(committed), so a fixed bug stays fixed.
"""

from __future__ import annotations

import inspect
import os
import re
import time
from pathlib import Path

import _fuzz_cases
import numpy as np
import pytest
from _fuzz_cases import (
    BOOL,
    CALLBACK,
    CHOICE,
    DENSITY,
    FLOAT,
    INDEX,
    INDEX1,
    INT,
    ITERS,
    POINTS,
    SIZE,
    SPECS,
    TRANSFORMS,
    WEIGHTS,
)
from _sandbox import Sandbox
from hypothesis import HealthCheck, Phase, given, note, settings
from hypothesis import strategies as st
from hypothesis.database import DirectoryBasedExampleDatabase

PROFILE = os.environ.get("SKINRS_FUZZ", "ci")
# examples per unit of Spec.weight
PER_WEIGHT = {"ci": 18, "long": 360}[PROFILE]
TIMEOUT = float(os.environ.get("SKINRS_FUZZ_TIMEOUT", "30"))
DATABASE = DirectoryBasedExampleDatabase(Path(__file__).parent / ".hypothesis" / "examples")

settings.register_profile(
    PROFILE,
    # failures are reported unshrunk (shrinking a 30 s hang takes hours)
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
    deadline=None,
    database=DATABASE,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    print_blob=True,
)
settings.load_profile(PROFILE)


@pytest.fixture(scope="module")
def sandbox():
    sb = Sandbox(timeout=TIMEOUT)
    t0 = time.perf_counter()
    yield sb
    sb.close()
    summary = f"fuzz profile {PROFILE}: {sb.calls} calls in {time.perf_counter() - t0:.0f} s"
    print(f"\n{summary}")
    report = os.environ.get("SKINRS_FUZZ_REPORT")
    if report:
        with open(report, "a") as f:
            f.write(summary + "\n")


# --------------------------------------------------------------------------------------------
# Ways to break an argument. Each returns (new value, expectation):
#   "same"    a re-typed or re-laid-out copy: the call must succeed;
#   "invalid" the call must raise ValueError/TypeError naming an argument;
#   "either"  an error as above, or a result satisfying the contract.
# --------------------------------------------------------------------------------------------

HUGE_INTS = [-1, 0, 2**31, 2**63 - 1, 2**64 - 1, 2**70, 10**12, -(2**63)]
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True)
SCALES = st.sampled_from([1e-320, 1e-300, 1e-160, 1e-80, 1e-12, 1e12, 1e70, 1e76, 1e160, 1e300])


def _entry(draw, a, value):
    """``a`` as float64 with one drawn entry set to ``value``."""
    a = np.array(a, dtype=np.float64, copy=True)
    if a.size:
        a.flat[draw(st.integers(0, a.size - 1))] = value
    return a


def _random_array(draw, dtype):
    shape = draw(st.tuples(st.integers(0, 6), st.integers(0, 5)))
    elements = ANY_FLOAT if dtype == np.float64 else st.integers(-(2**63), 2**63 - 1)
    return np.array(
        draw(st.lists(elements, min_size=shape[0] * shape[1], max_size=shape[0] * shape[1])),
        dtype=dtype,
    ).reshape(shape)


def _rows(draw, a):
    a = np.asarray(a)
    if not a.ndim or not len(a):
        return a
    idx = draw(st.lists(st.integers(0, len(a) - 1), max_size=2 * len(a) + 2))
    return a[np.array(idx, dtype=np.int64)]


def _ragged(a):
    a = np.asarray(a)
    if a.ndim == 2 and len(a) > 1:
        return [list(r)[:1] if i == 0 else list(r) for i, r in enumerate(a)]
    return [[1], [1, 2]]


# Each breaker: (fn(a, draw) -> new value, expectation)
def _array_breakers(kind):
    """Ways to break an array argument of ``kind``."""
    common = [
        (lambda a, d: None, "either"),  # None: a required argument's error, or the default
        (lambda a, d: d(st.text(max_size=8)), "invalid"),
        (lambda a, d: d(ANY_FLOAT), "invalid"),
        (lambda a, d: np.asarray(a).ravel(), "either"),
        (lambda a, d: np.asarray(a)[None], "invalid"),
        (lambda a, d: np.asarray(a)[:0], "either"),
        (lambda a, d: _rows(d, a), "either"),
        (lambda a, d: np.asarray(a).astype(complex) + 1j, "invalid"),
        (lambda a, d: np.asarray(a).astype(str), "invalid"),
        (lambda a, d: _ragged(a), "invalid"),
        (lambda a, d: np.asarray(a)[..., :-1], "either"),
        (lambda a, d: np.concatenate([a, a], axis=-1) if np.ndim(a) else a, "either"),
        (lambda a, d: _random_array(d, np.float64), "either"),
        (lambda a, d: _random_array(d, np.int64), "either"),
        (lambda a, d: np.asfortranarray(a), "same"),
        (lambda a, d: np.asarray(a).tolist(), "same"),
    ]
    if kind in (POINTS, WEIGHTS, TRANSFORMS):
        common += [
            (lambda a, d: _entry(d, a, d(st.sampled_from([np.nan, np.inf, -np.inf]))), "invalid"),
            (lambda a, d: _entry(d, a, d(ANY_FLOAT)), "either"),
            (lambda a, d: np.asarray(a, float) * d(SCALES), "either"),
            (lambda a, d: np.asarray(a, float) * d(st.floats(-1e6, 1e6)), "either"),
            (lambda a, d: np.asarray(a, float) + d(st.floats(-1e80, 1e80)), "either"),
            (
                lambda a, d: (
                    np.asarray(a, float)
                    + d(st.floats(0, 1e-3)) * np.sin(np.arange(np.size(a))).reshape(np.shape(a))
                ),
                "either",
            ),
            (lambda a, d: np.asarray(a, np.float32), "either"),
            (lambda a, d: np.zeros_like(np.asarray(a, float)), "either"),
        ]
    if kind == POINTS:
        common += [
            (lambda a, d: np.repeat(np.asarray(a, float)[:1], len(a), axis=0), "either"),
            (lambda a, d: np.asarray(a, float)[:, ::-1] if np.ndim(a) == 2 else a, "either"),
        ]
    if kind in (INDEX, INDEX1):
        common += [
            (lambda a, d: np.asarray(a) * 0 - d(st.integers(1, 2**63 - 1)), "invalid"),
            (lambda a, d: np.asarray(a) + d(st.integers(10**6, 2**62)), "invalid"),
            (lambda a, d: np.full(np.shape(a), 2**64 - 1, dtype=np.uint64), "invalid"),
            (lambda a, d: np.asarray(a, float) + d(st.floats(0.01, 0.99)), "invalid"),
            (lambda a, d: _entry(d, a, np.nan), "invalid"),
            (lambda a, d: np.asarray(a, np.int32), "same"),
            (lambda a, d: np.asarray(a, np.float64), "same"),
            (lambda a, d: np.asarray(a, bool), "either"),
            (lambda a, d: np.asarray(a) % d(st.integers(1, 4)), "either"),
            (lambda a, d: np.asarray(a)[:, ::-1] if np.ndim(a) == 2 else a, "either"),
        ]
    return common


def _scalar_breakers(kind):
    ints = [(lambda a, d, x=x: x, "either") for x in HUGE_INTS] + [
        (lambda a, d: d(st.integers(-(2**70), 2**70)), "either"),
        (lambda a, d: d(st.integers(-3, 40)), "either"),
        (lambda a, d: 1.5, "invalid"),
        (lambda a, d: "3", "invalid"),
        (lambda a, d: True, "either"),
        (lambda a, d: np.int32(2), "either"),
        (lambda a, d: float("nan"), "invalid"),
        (lambda a, d: None, "either"),
        (lambda a, d: 1 + 2j, "invalid"),
    ]
    floats = [
        (lambda a, d: d(ANY_FLOAT), "either"),
        (lambda a, d: d(SCALES), "either"),
        (lambda a, d: float("nan"), "invalid"),
        (lambda a, d: "x", "invalid"),
        (lambda a, d: 1j, "invalid"),
        (lambda a, d: None, "either"),
        (lambda a, d: np.float32(0.5), "either"),
    ]
    choices = [
        (lambda a, d: d(st.text(max_size=12)), "either"),
        (
            lambda a, d: d(st.sampled_from(["pq30Y", "Q", "zzzz!!", "pq1.2/10Y", "ri", "o2p"])),
            "either",
        ),
        (lambda a, d: "a" * 10_000, "either"),
        (lambda a, d: d(st.integers()), "either"),
        (lambda a, d: None, "either"),
    ]
    callbacks = [
        (lambda a, d: 5, "invalid"),
        (lambda a, d: "print", "invalid"),
        (lambda a, d: _fuzz_cases.stop, "either"),
        (lambda a, d: _fuzz_cases.keep_going, "same"),
        (lambda a, d: _fuzz_cases.interrupt, "either"),
        (lambda a, d: _fuzz_cases.own, "either"),
    ]
    # counts of work (steps, iterations): huge values are legitimate long runs, not probed
    iters = [(lambda a, d, x=x: x, "invalid") for x in (-1, 0, 1.5, "3", 2**70, 1j)] + [
        (lambda a, d: None, "either"),
        (lambda a, d: d(st.integers(1, 5)), "either"),
        (lambda a, d: np.int32(3), "either"),
    ]
    # sampling densities: the meshers' time grows with them (Triangle takes ~10 s for 300
    # samples per bone), so only moderate ones are probed, and absurd ones must be refused
    density = [(lambda a, d, x=x: x, "invalid") for x in (0, -1.0, float("nan"), "x", 1j)] + [
        (lambda a, d: d(st.floats(0.05, 8)), "either"),
        (lambda a, d: d(st.sampled_from([1e9, 1e300, float("inf")])), "invalid"),
    ]
    # output sizes: beyond memory they must be refused; hundreds of millions are legitimate
    # (and take a while), so they are not probed
    size = [(lambda a, d, x=x: x, "invalid") for x in (-1, 1.5, "3", 2**70, 10**12, 2**63 - 1)]
    size += [(lambda a, d: d(st.integers(0, 10**5)), "either"), (lambda a, d: None, "either")]
    kinds = {DENSITY: density, SIZE: size, INT: ints, ITERS: iters, FLOAT: floats, CHOICE: choices}
    return {**kinds, BOOL: ints, CALLBACK: callbacks}[kind]


SCALAR_KINDS = (INT, ITERS, FLOAT, CHOICE, BOOL, CALLBACK, DENSITY, SIZE)


def breakers(kind):
    if kind in SCALAR_KINDS:
        return _scalar_breakers(kind)
    return _array_breakers(kind)


# --------------------------------------------------------------------------------------------
# Outcome checks
# --------------------------------------------------------------------------------------------

ALLOWED = ("ValueError", "TypeError")


def _names_an_argument(message: str, names) -> bool:
    return any(re.search(rf"(?<![A-Za-z_]){re.escape(n)}(?![A-Za-z_])", message) for n in names)


def check_outcome(out, spec, kwargs, arg, expect):
    desc = f"{spec.target} with {arg} broken ({expect})"
    if out.error is not None:
        assert out.error not in ("InternalError", "PanicException"), (
            f"{desc}: Rust panic: {out.message}"
        )
        if out.raised("KeyboardInterrupt"):
            assert spec.kinds.get(arg) == CALLBACK, f"{desc}: KeyboardInterrupt without a callback"
            return
        if out.error == "Own":  # the callback's own exception, passed through unchanged
            assert spec.kinds.get(arg) == CALLBACK, desc
            return
        assert expect != "same", f"{desc}: a valid re-typed input raised {out.error}: {out.message}"
        assert out.raised(*ALLOWED), f"{desc}: raised {out.error}: {out.message}"
        assert out.message.strip(), f"{desc}: {out.error} without a message"
        if expect == "invalid":  # a bad shape, dtype, value or range: say which argument
            assert _names_an_argument(out.message, list(kwargs)), (
                f"{desc}: the message names no argument: {out.message!r}"
            )
        return
    assert expect != "invalid", f"{desc}: invalid input accepted, returned {type(out.value)}"
    spec.contract(out.value, kwargs)


def _source(fn) -> str:
    try:
        return inspect.getsource(fn).strip()
    except OSError:  # lambdas made in a comprehension
        return repr(fn)


def _all_specs():
    return sorted(SPECS)


@pytest.mark.parametrize("name", _all_specs())
def test_public_function(name, sandbox):
    spec = SPECS[name]
    base = spec.build()
    args = sorted(spec.kinds)

    @settings(max_examples=spec.weight * PER_WEIGHT)
    @given(data=st.data())
    def run(data):
        arg = data.draw(st.sampled_from(args), label="argument")
        options = breakers(spec.kinds[arg])
        which = data.draw(st.integers(0, len(options) - 1), label="breaker")
        fn, expect = options[which]
        note(f"breaker: {_source(fn)}")
        kwargs = dict(base)
        start = kwargs.get(arg)
        if start is None and spec.present and arg in spec.present:
            start = spec.present[arg]
        scalar = spec.kinds[arg] in SCALAR_KINDS
        value = fn(start, data.draw) if start is not None or scalar else None
        if start is None and not scalar:
            expect = "either"
        if value is None and arg not in spec.optional and arg in base:
            expect = "invalid" if base[arg] is not None else "either"
        kwargs[arg] = value
        kwargs = {k: v for k, v in kwargs.items() if not (v is None and k in spec.optional)}
        out = sandbox.call(spec.target, **kwargs)
        check_outcome(out, spec, kwargs, arg, expect)

    # one example-database key per function (the inner test's source is shared)
    run._hypothesis_internal_add_digest = name.encode()
    run()


# --------------------------------------------------------------------------------------------
# Readers
# --------------------------------------------------------------------------------------------

READER_EXAMPLES = {"ci": 100, "long": 2500}[PROFILE]
BAD_TOKENS = ["nan", "inf", "-inf", "1e400", "x", "", "-1", "0", "99999999999999999999", "#"]


def _cut(text, d):
    """The file cut at a drawn byte (a cut inside a line, or at a line end)."""
    return text[: d(st.integers(0, max(len(text) - 1, 0)))]


def _mutations():
    # (fn(text, draw) -> bytes or str, expectation)
    def lines_op(op):
        def f(text, d):
            lines = text.splitlines(keepends=True)
            i = d(st.integers(0, len(lines) - 1))
            j = d(st.integers(0, len(lines) - 1))
            return "".join(op(lines, i, j))

        return f

    def token_op(text, d):
        toks = re.split(r"(\s+)", text)
        words = [k for k, t in enumerate(toks) if t.strip()]
        k = words[d(st.integers(0, len(words) - 1))]
        toks[k] = d(st.sampled_from(BAD_TOKENS) | st.text(max_size=6))
        return "".join(toks)

    def number_op(text, d):
        toks = re.split(r"(\s+)", text)
        nums = [k for k, t in enumerate(toks) if re.fullmatch(r"-?\d+(\.\d*)?", t)]
        k = nums[d(st.integers(0, len(nums) - 1))]
        toks[k] = str(d(st.integers(-(2**70), 2**70) | st.sampled_from([0, 1, 2, 10**12])))
        return "".join(toks)

    return [
        (_cut, "either"),
        (lines_op(lambda L, i, j: L[:i] + L[i + 1 :]), "either"),  # a line dropped
        (lines_op(lambda L, i, j: L[: i + 1] + [L[i]] + L[i + 1 :]), "either"),  # doubled
        (lines_op(lambda L, i, j: L[:i] + [L[j]] + L[i + 1 :]), "either"),  # replaced
        (lines_op(lambda L, i, j: [x.rstrip("\n") + " " for x in L]), "either"),
        (token_op, "either"),
        (number_op, "either"),
        (lambda t, d: "", "either"),
        (lambda t, d: d(st.binary(max_size=64)), "either"),
        (lambda t, d: t.replace("\n", "\r\n"), "same"),
        (lambda t, d: t + d(st.text(max_size=20)), "either"),
    ]


MUTATIONS = _mutations()


@pytest.mark.parametrize("reader", sorted(_fuzz_cases.READER_FILES))
def test_reader(reader, sandbox, tmp_path_factory):
    fname, text = _fuzz_cases.READER_FILES[reader]
    folder = tmp_path_factory.mktemp(reader)

    @settings(max_examples=READER_EXAMPLES)
    @given(data=st.data())
    def run(data):
        which = data.draw(st.integers(0, len(MUTATIONS) - 1), label="mutation")
        fn, expect = MUTATIONS[which]
        note(f"mutation: {_source(fn)}")
        content = fn(text, data.draw)
        path = folder / fname
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, newline="")
        note(f"file: {path.read_bytes()!r}")
        out = sandbox.call(f"skinrs.io:{reader}", str(path))
        desc = f"{reader} on a mutated file ({expect})"
        if out.error is not None:
            assert expect != "same", f"{desc}: raised {out.error}: {out.message}"
            assert out.raised("ValueError"), f"{desc}: raised {out.error}: {out.message}"
            assert str(path) in out.message, f"{desc}: the message names no file: {out.message}"
            return
        assert expect != "invalid", f"{desc}: accepted"
        _fuzz_cases.reader_contract(reader, out.value)

    run._hypothesis_internal_add_digest = reader.encode()
    run()
