"""Seed 001's LSSVM: the bordered system, the online factor update, the model file."""

import io
import math
import struct
import zipfile

import numpy as np
import pytest

from ato_nodes.core.control import identification as ident
from ato_nodes.core.control import lssvm
from ato_nodes.core.base.errors import ScenarioError

LAYOUT = lssvm.Layout(2, 1, 1)


def train_like_samples(n, seed=0):
    """Regressors and increments of a lagged train-like map, with noise: speeds in
    0-90 m/s, commands in +-60 N/kN."""
    rng = np.random.default_rng(seed)
    v1 = rng.uniform(0, 90, n)
    v2 = v1 - rng.normal(0, 0.1, n)
    u = rng.uniform(-60, 60, n)
    t = 0.3 * 0.00925 * (u - (0.37 + 0.019 * v1 + 0.00135 * v1 ** 2)) + 0.3 * (v1 - v2)
    return np.column_stack([v1, v2, u]), t + rng.normal(0, 0.005, n)


def bordered_solution(model, x, t):
    """alpha and b from the full (n+1) system of the LSSVM, solved directly."""
    z = model.to_unit(x)
    n = len(t)
    system = np.zeros((n + 1, n + 1))
    system[0, 1:] = system[1:, 0] = 1.0
    system[1:, 1:] = model._kernel(z, z) + np.eye(n) / model.mu
    solution = np.linalg.solve(system, np.concatenate([[0.0], t]))
    return solution[1:], solution[0]


def test_the_cholesky_solve_is_the_bordered_system_solution():
    x, t = train_like_samples(300)
    model = lssvm.fit(LAYOUT, x, t, mu=500.0, delta=0.5)
    alpha, bias = bordered_solution(model, x, t)
    np.testing.assert_allclose(model.alpha, alpha, rtol=1e-7, atol=1e-9)
    assert model.bias == pytest.approx(bias, rel=1e-9)
    assert abs(model.alpha.sum()) < 1e-8  # the constraint row: sum alpha = 0


def test_the_analytic_gradient_matches_finite_differences():
    x, t = train_like_samples(200)
    model = lssvm.fit(LAYOUT, x, t, mu=100.0, delta=0.7)
    point = np.array([40.0, 39.9, 12.0])
    value, gradient = model.linearise(point)
    assert value == pytest.approx(float(model.increment(point)[0]), rel=1e-12)
    for i, step in enumerate((1e-3, 1e-3, 1e-3)):
        shifted = point.copy()
        shifted[i] += step
        numeric = (model.increment(shifted)[0] - model.increment(point - (shifted - point))[0]) \
            / (2 * step)
        assert gradient[i] == pytest.approx(numeric, rel=1e-5, abs=1e-10)


@pytest.mark.parametrize("columns", range(1, 20))
def test_the_kernel_loops_give_the_bits_of_the_numpy_expression(columns):
    """Differences and exponents as `z - support` and np.einsum give them (its order of
    summing squares: blocks of eight, tails, lanes) for every column count."""
    rng = np.random.default_rng(columns)
    z = rng.uniform(-1.0, 2.0, columns)
    support = rng.uniform(-1.0, 2.0, (500, columns)) * 10.0 ** rng.uniform(-3, 3, (500, 1))
    difference, exponent = np.empty_like(support), np.empty(len(support))
    lssvm._rbf_exponents(z, support, 0.37, difference, exponent)
    expected = z - support
    np.testing.assert_array_equal(difference, expected)
    np.testing.assert_array_equal(exponent, -np.einsum("ij,ij->i", expected, expected) / 0.37)


@pytest.mark.skipif(lssvm.linearise_dictionary is lssvm._linearise_dictionary,
                    reason="numba is not installed")
def test_linearise_gives_the_same_bits_compiled_or_not(monkeypatch):
    x, t = train_like_samples(300)
    model = lssvm.fit(LAYOUT, x, t, mu=500.0, delta=0.5, window=20)
    for row, target in zip(*train_like_samples(15, seed=2), strict=True):
        model.add(row, target)
    points = train_like_samples(20, seed=3)[0]
    compiled = [model.linearise(point) for point in points]
    monkeypatch.setattr(lssvm, "linearise_dictionary", lssvm._linearise_dictionary)
    for point, (value, gradient) in zip(points, compiled, strict=True):
        python_value, python_gradient = model.linearise(point)
        assert python_value == value
        np.testing.assert_array_equal(python_gradient, gradient)


@pytest.mark.parametrize("window, updates", [(500, 500), (60, 500)])
def test_online_updates_stay_within_1e6_kmh_of_a_fresh_solve(window, updates):
    x, t = train_like_samples(900)
    new_x, new_t = train_like_samples(updates, seed=1)
    model = lssvm.fit(LAYOUT, x, t, mu=6000.0, delta=0.5, window=window)
    for row, target in zip(new_x, new_t, strict=True):
        assert model.add(row, target)
    assert model.added == updates and model.size == 900 + min(window, updates)
    assert model.forgotten == max(0, updates - window)
    fresh = model.refit()
    check = np.concatenate([x[:200], new_x[-200:]])
    drift = np.abs(fresh.increment(check) - model.increment(check)).max() * 3.6
    assert drift < 1e-6
    # forgetting keeps the identification samples and the newest corrections
    kept_x, _ = model.samples
    np.testing.assert_allclose(kept_x[:900], x)
    np.testing.assert_allclose(kept_x[900:], new_x[updates - min(window, updates):])


def test_a_numerical_copy_of_a_sample_is_refused_by_the_schur_guard():
    x, t = train_like_samples(100)
    model = lssvm.fit(LAYOUT, x, t, mu=1e12, delta=0.5, window=10)
    assert not model.add(x[3], t[3] + 0.01)
    assert model.rejected == 1 and model.size == 100
    assert np.all(np.isfinite(model.alpha))


def test_a_model_without_a_window_takes_no_corrections():
    x, t = train_like_samples(50)
    model = lssvm.fit(LAYOUT, x, t, mu=10.0, delta=0.5)
    assert not model.add(x[0] + 1.0, 0.0) and model.size == 50


def save(tmp_path, model, name="model.npz", period=0.3, train="crh380al"):
    path = tmp_path / name
    lssvm.ModelFile(model, period, {"plant.train": train}, np.array([10.0, 50.0]), 20.0,
                    np.zeros((2, 1 + LAYOUT.size))).save(path)
    return path


def test_the_model_file_round_trips(tmp_path):
    x, t = train_like_samples(120)
    model = lssvm.fit(LAYOUT, x, t, mu=300.0, delta=0.6)
    loaded = lssvm.load_model(save(tmp_path, model))
    assert loaded.period == 0.3 and loaded.train == {"plant.train": "crh380al"}
    assert loaded.lssvm.layout == LAYOUT
    # re-solved from the stored samples on load: equal to rounding, and every load alike
    np.testing.assert_allclose(loaded.lssvm.increment(x[:20]), model.increment(x[:20]),
                               rtol=1e-9, atol=1e-12)
    again = lssvm.load_model(tmp_path / "model.npz")
    np.testing.assert_array_equal(again.lssvm.increment(x[:20]), loaded.lssvm.increment(x[:20]))


def test_a_model_loaded_again_is_its_own_copy_of_the_same_solve(tmp_path):
    x, t = train_like_samples(120)
    path = save(tmp_path, lssvm.fit(LAYOUT, x, t, mu=300.0, delta=0.6))
    first = lssvm.load_model(path, window=10)
    assert first.lssvm.add(x[0] + 5.0, 0.1)  # a correction changes this copy only
    second = lssvm.load_model(path, window=10)
    assert second.lssvm.size == 120 and second.lssvm.added == 0
    lssvm._solved_model.cache_clear()
    fresh = lssvm.load_model(path, window=10)
    assert second.lssvm.bias == fresh.lssvm.bias
    np.testing.assert_array_equal(second.lssvm.alpha, fresh.lssvm.alpha)
    for point in x[:5]:
        assert second.lssvm.linearise(point)[0] == fresh.lssvm.linearise(point)[0]
    with pytest.raises(ValueError, match="read-only"):
        second.arx_coefficients[0, 0] = 1.0  # shared by every copy
    save(tmp_path, lssvm.fit(LAYOUT, x[:100], t[:100], mu=300.0, delta=0.6))
    assert lssvm.load_model(path, window=10).lssvm.size == 100  # a changed file: solved anew


def one_line_error(path, match):
    with pytest.raises(ScenarioError, match=match) as caught:
        lssvm.load_model(path)
    assert "\n" not in str(caught.value)


def test_a_missing_corrupt_or_truncated_model_file_is_one_line(tmp_path):
    x, t = train_like_samples(120)
    good = save(tmp_path, lssvm.fit(LAYOUT, x, t, mu=300.0, delta=0.6))
    one_line_error(tmp_path / "absent.npz", "cannot read model file")
    (tmp_path / "text.npz").write_text("not a model")
    one_line_error(tmp_path / "text.npz", "not a readable .npz")
    data = good.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[:len(data) // 2])
    one_line_error(tmp_path / "cut.npz", "not a readable .npz")


def test_a_model_file_whose_coefficients_do_not_solve_its_samples_is_refused(tmp_path):
    x, t = train_like_samples(120)
    good = save(tmp_path, lssvm.fit(LAYOUT, x, t, mu=300.0, delta=0.6))
    with np.load(good) as archive:
        fields = {name: archive[name] for name in archive.files}
    fields["targets"] = fields["targets"] * 1.01
    np.savez(tmp_path / "edited.npz", **fields)
    one_line_error(tmp_path / "edited.npz", "do not solve its samples")
    del fields["alpha"]
    np.savez(tmp_path / "short.npz", **fields)
    one_line_error(tmp_path / "short.npz", "lacks the field alpha")


def test_hyperparameters_that_make_the_kernel_matrix_singular_are_one_line(tmp_path):
    x, t = train_like_samples(60)
    x[1] = x[0]  # two identical regressors: singular kernel matrix without regularisation
    with pytest.raises(ValueError, match="numerically singular"):
        lssvm.fit(LAYOUT, x, t, mu=1e300, delta=0.5)
    model = lssvm.fit(LAYOUT, x, t, mu=100.0, delta=0.5)
    path = save(tmp_path, model)
    with np.load(path) as archive:
        fields = {name: archive[name] for name in archive.files}
    fields["mu"] = np.array(1e300)
    np.savez(tmp_path / "singular.npz", **fields)
    one_line_error(tmp_path / "singular.npz", "numerically singular")


def test_a_non_archive_zip_error_is_one_line(tmp_path):
    with zipfile.ZipFile(tmp_path / "empty.npz", "w"):
        pass
    one_line_error(tmp_path / "empty.npz", "lacks the field format")


def test_samples_pair_each_step_with_its_history():
    speeds = np.arange(10.0) ** 2
    commands = np.arange(10.0) * 10
    x, t = lssvm.Layout(2, 2, 1).samples(speeds, commands)
    # the first step with a full history is k = 3: y(2), y(1), u(1), u(0)
    np.testing.assert_array_equal(x[0], [4.0, 1.0, 10.0, 0.0])
    assert t[0] == 9.0 - 4.0
    np.testing.assert_array_equal(lssvm.Layout(2, 2, 1).regressor(speeds[:4], commands[:4]),
                                  [9.0, 4.0, 20.0, 10.0])


def test_the_split_interleaves_three_of_five_for_training():
    train, test = ident.split(1500, 900)
    assert len(train) == 900 and len(test) == 600
    assert set(train) | set(test) == set(range(1500))
    assert max(np.diff(train)) <= 2 and max(np.diff(test)) <= 3


@pytest.mark.slow
def test_the_hyperparameter_search_finds_a_fit_better_than_the_box_corner():
    x, t = train_like_samples(240)
    search = ident.search_hyperparameters(LAYOUT, x, t, seed=3, population=8, iterations=6)
    parts = ident.validation_split(x, t)
    corner = ident.validation_rmse(LAYOUT, *parts, 10.0 ** ident.LOG_MU[0], ident.DELTA[1])
    assert search.rmse < corner and math.isfinite(search.rmse)
    assert search.result.evaluations == 8 * 7
    assert 10.0 ** ident.LOG_MU[0] <= search.mu <= 10.0 ** ident.LOG_MU[1]


def test_the_excitation_covers_the_speed_range_in_both_directions():
    rows = np.array(ident.excitation_table(5, 3000.0, 80.0))
    assert rows[0, 1] == 0.0 and rows[-1, 1] == 0.0
    assert np.all(np.diff(rows[:, 0]) > 0)
    assert rows[:, 1].max() > 0.7 * 80.0 and rows[:, 1].max() <= 80.0 + 5 / 3.6
    changes = np.diff(rows[:, 1])
    assert (changes > 1.0).sum() >= 5 and (changes < -1.0).sum() >= 5


def members(path) -> dict[str, bytes]:
    """A model file's members, as stored (each an .npy file)."""
    with zipfile.ZipFile(path) as archive:
        return {info.filename: archive.read(info) for info in archive.infolist()}


def write_members(path, stored: dict[str, bytes]):
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in stored.items():
            archive.writestr(name, data)
    return path


def npy(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


@pytest.fixture
def model_file(tmp_path):
    x, t = train_like_samples(60)
    return save(tmp_path, lssvm.fit(LAYOUT, x, t, mu=300.0, delta=0.6))


def test_a_member_that_expands_beyond_the_bound_is_refused_from_the_zip_directory(
        tmp_path, model_file):
    """The directory's uncompressed size (a deflate bomb's 8 GB, declared here for 1 GiB
    without writing it) is read before anything is decompressed."""
    data = bytearray(model_file.read_bytes())
    entry = data.rindex(b"regressors.npy") - 46  # its central-directory record
    assert data[entry:entry + 4] == b"PK\x01\x02"
    struct.pack_into("<I", data, entry + 24, 1 << 30)
    (tmp_path / "bomb.npz").write_bytes(data)
    one_line_error(tmp_path / "bomb.npz", "its arrays expand to 1024 MiB, more than 64 MiB")


def test_an_array_header_claiming_more_data_than_its_member_holds_is_refused(
        tmp_path, model_file):
    stored = members(model_file)
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False,
                                                  "shape": (10 ** 12,)})  # 8 TB
    stored["targets.npy"] = header.getvalue() + bytes(64)
    write_members(tmp_path / "claims.npz", stored)
    one_line_error(tmp_path / "claims.npz", "targets claims more data than it holds")


@pytest.mark.parametrize("name, array, message", [
    ("arx_width", np.array(np.nan), "arx_width holds non-finite numbers"),
    ("arx_coefficients", np.full((2, 1 + LAYOUT.size), np.nan),
     "arx_coefficients holds non-finite numbers"),
    ("bias", np.array(np.inf), "bias holds non-finite numbers"),
    ("arx_width", np.array(0.0), "arx_width and period must be positive"),
    ("offset", np.zeros(LAYOUT.size, np.float32),
     "offset is a 1-dimensional float32 array, not a 1-dimensional float64 one"),
    ("regressors", np.zeros(10), "regressors is a 1-dimensional float64 array, not a "
     "2-dimensional float64 one"),
    ("layout", np.array([2.0, 1.0, 1.0]), "layout is a 1-dimensional float64 array, not a "
     "1-dimensional integer one"),
    ("train", np.array('["crh380al"]'), "train must be a JSON object"),
    ("arx_centres", np.zeros(0), "the multi-model's arrays do not match its layout"),
])
def test_every_member_is_checked_for_dtype_shape_and_finiteness(
        tmp_path, model_file, name, array, message):
    stored = members(model_file)
    stored[f"{name}.npy"] = npy(array)
    one_line_error(write_members(tmp_path / "edited.npz", stored), message)


def test_only_the_members_the_format_names_are_read(tmp_path, model_file):
    stored = members(model_file)
    stored["unread.npy"] = b"not an array"
    assert lssvm.load_model(write_members(tmp_path / "extra.npz", stored)).lssvm.size == 60


def test_a_window_that_would_make_the_factor_too_large_is_one_line(model_file):
    """gpc.window 100000 would ask for a (60 + 100000)^2 factor: 75 GiB."""
    for window in (100000, lssvm.MAX_DICTIONARY - 59):
        with pytest.raises(ScenarioError, match=f"its 60 samples and gpc.window {window} "
                                                "exceed the 8192 samples a model may hold"):
            lssvm.load_model(model_file, window)


def test_a_model_file_that_is_not_a_regular_file_is_one_line(tmp_path):
    one_line_error(tmp_path, "is a directory")
    one_line_error("/dev/zero", "is not a regular file")
