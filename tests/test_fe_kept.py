"""Kept solutions (femstudy.fe.kept): a repeated solve factorises nothing and answers as a
direct solve does; a different or corrupted store is never used."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femstudy.fe import linsolve
from femstudy.fe.kept import RTOL, KeptSolutions, fingerprint


def laplacian_3d(n: int = 12) -> sp.csr_matrix:
    """The 7-point Laplacian on an n³ grid plus a small shift: SPD, condition ~ 100 n²."""
    one = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    eye = sp.identity(n)
    A = sp.kron(sp.kron(one, eye), eye) + sp.kron(sp.kron(eye, one), eye) + sp.kron(sp.kron(eye, eye), one)
    return (A + 1e-3 * sp.identity(n ** 3)).tocsr()


def kept(A, folder):
    return KeptSolutions(A, lambda: linsolve.factorize(A, "superlu"), folder)


def test_a_repeated_solve_is_served_without_factorising(tmp_path):
    A = laplacian_3d()
    rng = np.random.default_rng(1)
    B = rng.standard_normal((A.shape[0], 3))
    first = kept(A, tmp_path)
    X = first.solve(B)
    assert first.factorisations == 1
    first.close()
    assert (tmp_path / f"{fingerprint(A)}.npz").is_file()

    second = kept(A, tmp_path)
    assert second.loaded == 3
    combination = B @ [0.3, -2.0, 5.0]  # any combination of kept right-hand sides
    x = second.solve(combination)
    assert second.factorisations == 0 and second.served == 1
    exact = spla.spsolve(A.tocsc(), combination)
    assert np.linalg.norm(A @ x - combination) <= RTOL * np.linalg.norm(combination)
    assert np.allclose(x, exact, rtol=0, atol=1e-9 * np.abs(exact).max())
    assert np.allclose(second.solve(B), X, rtol=0, atol=1e-9 * np.abs(X).max())
    assert second.factorisations == 0


def test_node_blocks_are_kept_under_their_own_fingerprint_and_served(tmp_path):
    """K_ff as BSR of 3×3 node blocks (the study's, with whole-node clamps) is kept and served
    without a CSR copy; the same matrix as CSR is another key, so neither store is taken for
    the other's format."""
    A = laplacian_3d()
    blocks = A.tobsr(blocksize=(3, 3))
    assert fingerprint(blocks) != fingerprint(A) and fingerprint(blocks) == fingerprint(blocks.copy())
    b = np.random.default_rng(4).standard_normal(A.shape[0])
    first = kept(blocks, tmp_path)
    x = first.solve(b)
    first.close()
    second = kept(blocks, tmp_path)
    assert second.A.format == "bsr" and second.loaded == 1
    assert np.allclose(second.solve(2 * b), 2 * x, rtol=0, atol=1e-12 * np.abs(x).max())
    assert second.factorisations == 0 and kept(A, tmp_path).loaded == 0
    exact = spla.spsolve(A.tocsc(), b)
    assert np.allclose(x, exact, rtol=0, atol=1e-9 * np.abs(exact).max())


def test_a_new_direction_is_solved_and_kept(tmp_path):
    A = laplacian_3d()
    rng = np.random.default_rng(2)
    b1, b2 = rng.standard_normal((2, A.shape[0]))
    solver = kept(A, tmp_path)
    solver.solve(b1)
    x = solver.solve(b1 + b2)  # half in span, half new: one factorisation serves both
    assert solver.factorisations == 1 and solver.U.shape[1] == 2
    assert np.linalg.norm(A @ x - (b1 + b2)) <= RTOL * np.linalg.norm(b1 + b2)
    assert np.allclose(solver.U.T @ solver.U, np.eye(2), atol=1e-12)


@pytest.mark.parametrize("change", ["matrix", "store"])
def test_a_changed_matrix_or_a_corrupted_store_is_not_used(tmp_path, change):
    A = laplacian_3d()
    b = np.random.default_rng(3).standard_normal(A.shape[0])
    first = kept(A, tmp_path)
    first.solve(b)
    first.close()
    if change == "matrix":  # one entry changed: another fingerprint, so the store is not found
        A = A.copy()
        A[0, 0] *= 1.001
    else:  # the right name, wrong solutions: the check against A on loading refuses them
        path = tmp_path / f"{fingerprint(A)}.npz"
        with np.load(path) as stored:
            parts = dict(stored)
        parts["Z"] = parts["Z"] * 1.01
        with open(path, "wb") as out:
            np.savez(out, **parts)
    second = kept(A, tmp_path)
    assert second.loaded == 0
    x = second.solve(b)
    assert second.factorisations == 1
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_a_set_over_the_size_limit_is_not_stored(tmp_path, monkeypatch):
    from femstudy.fe import kept as kept_module

    A = laplacian_3d(6)
    monkeypatch.setattr(kept_module, "MAX_STORED_BYTES", 8 * A.shape[0])  # less than one pair
    solver = kept(A, tmp_path)
    x = solver.solve(np.ones(A.shape[0]))
    solver.close()
    assert not list(tmp_path.iterdir())
    assert np.linalg.norm(A @ x - 1.0) <= 1e-10 * np.sqrt(A.shape[0])


def test_a_set_grown_from_another_runs_right_hand_sides_stays_orthonormal_and_exact(tmp_path):
    """A run keeps two right-hand sides that are combinations of six unit loads up to round-off
    (1e-9: another run's unit fields); a later run asks for the six: the set grows by their
    other directions, stays orthonormal, and a third run is served the six exactly."""
    A = laplacian_3d()
    rng = np.random.default_rng(4)
    B6 = rng.standard_normal((A.shape[0], 6))
    B2 = B6 @ rng.standard_normal((6, 2)) + 1e-9 * rng.standard_normal((A.shape[0], 2))
    exact = spla.spsolve(A.tocsc(), B6)
    first = kept(A, tmp_path)
    first.solve(B2)
    first.close()
    grown = kept(A, tmp_path)
    X = grown.solve(B6)
    assert np.allclose(grown.U.T @ grown.U, np.eye(grown.U.shape[1]), rtol=0, atol=1e-12)
    grown.close()
    served = kept(A, tmp_path)
    assert served.loaded == grown.U.shape[1]
    again = served.solve(B6)
    assert served.factorisations == 0
    for x in (X, again):
        assert np.abs(x - exact).max() <= 1e-9 * np.abs(exact).max()


def test_the_run_command_can_turn_kept_solutions_off():
    from femstudy.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["run", "case.toml"]).keep_solutions is True
    assert parser.parse_args(["run", "case.toml", "--no-kept-solutions"]).keep_solutions is False


def test_an_unreadable_store_or_an_unwritable_folder_costs_a_factorisation_not_the_run(tmp_path):
    A = laplacian_3d(6)
    b = np.ones(A.shape[0])
    (tmp_path / f"{fingerprint(A)}.npz").write_bytes(b"PK\x03\x04 not a zip archive")
    solver = kept(A, tmp_path)
    assert solver.loaded == 0
    x = solver.solve(b)
    assert solver.factorisations == 1 and np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    solver = kept(A, blocked / "solutions")  # its parent is a file: nothing can be stored there
    solver.solve(b)
    solver.close()
    assert not (blocked / "solutions").exists()


def test_modes_are_kept_beside_the_solutions_and_checked_before_use(tmp_path, caplog):
    """femstudy.fe.modal: a second analysis of the same K and M reads its modes back (no
    iteration, no factorisation); a store that fails the residual check, or a changed mass
    matrix, costs an analysis, never a wrong mode."""
    from dataclasses import replace

    from fe_cases import LENGTH, R_IN, R_OUT, clamped_both_ends, tube
    from femstudy.fe import assemble, factorize, solve_modal
    from femstudy.fe.geometry import tube_mesh
    from femstudy.materials import BoneMaterials

    system = tube(1, 12, 12, 2)
    bc = clamped_both_ends(system)
    plain = solve_modal(factorize(system, bc), k=4)
    first = solve_modal(factorize(system, bc, "superlu", keep=tmp_path), k=4)
    fs = factorize(system, bc, "superlu", keep=tmp_path)
    again = solve_modal(fs, k=4)
    assert (plain.kept, first.kept, again.kept) == (False, False, True)
    assert fs.factor.factorisations == 0 and fs.factor.served == 0  # not even a kept solve
    assert np.array_equal(again.frequency_Hz, first.frequency_Hz) and np.array_equal(again.shapes, first.shapes)
    assert again.frequency_Hz == pytest.approx(plain.frequency_Hz, rel=1e-8)  # another solver's analysis

    (store,) = tmp_path.glob("*-modes4-*.npz")
    with np.load(store) as stored:
        good = dict(stored)
    # ω² 0.1 % off fails the residual check; 5e-7 off passes it (rtol 1e-6), not the Rayleigh quotient's
    for factor in (1.001, 1 + 5e-7):
        with open(store, "wb") as out:
            np.savez(out, **{**good, "omega2": good["omega2"] * factor})
        caplog.clear()
        redone = solve_modal(factorize(system, bc, "superlu", keep=tmp_path), k=4)
        assert not redone.kept and "ignoring kept modes" in caplog.text
        assert redone.frequency_Hz == pytest.approx(plain.frequency_Hz, rel=1e-8)

    bone = BoneMaterials()
    heavy = replace(bone, cortical=replace(bone.cortical, density_t_mm3=2 * bone.cortical.density_t_mm3))
    heavier = assemble(tube_mesh(LENGTH, R_OUT, R_IN, 1, 12, 12), heavy, order=2)
    moved = solve_modal(factorize(heavier, clamped_both_ends(heavier), "superlu", keep=tmp_path), k=4)
    assert not moved.kept and len(list(tmp_path.glob("*-modes4-*.npz"))) == 2
    assert moved.frequency_Hz[0] < 0.9 * plain.frequency_Hz[0]


def test_a_store_reads_back_what_was_stored_compressed_or_not_and_a_truncated_one_is_refused(tmp_path, caplog):
    """read_store reads np.savez's uncompressed members straight from the file; it reads what
    np.load reads, compressed members too, and a store cut short is unreadable, not wrong."""
    from femstudy.fe.kept import read_store, write_store

    rng = np.random.default_rng(5)
    arrays = {"U": np.asfortranarray(rng.standard_normal((300, 7))), "e": rng.random(7),
              "method": np.array("pardiso"), "ids": np.arange(12, dtype=np.int32).reshape(3, 4)}
    stored, packed = tmp_path / "stored.npz", tmp_path / "packed.npz"
    assert write_store(stored, "test", **arrays)
    np.savez_compressed(packed, **arrays)
    for path in (stored, packed):
        back = read_store(path, list(arrays), "test")
        with np.load(path) as reference:
            for name, value in arrays.items():
                assert back[name].dtype == value.dtype and np.array_equal(back[name], reference[name])
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(stored.read_bytes()[: stored.stat().st_size // 2])
    assert read_store(truncated, list(arrays), "test") is None
    assert "ignoring unreadable kept test" in caplog.text
