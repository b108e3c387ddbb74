"""Order-fixed versions of the four MuJoCo Warp 4.0 solver kernels whose float atomics race.

With contacts and constraint rows in a canonical order (determinism.py), MuJoCo Warp's Newton
step still differs from run to run by ~1e-4 in qvel: four kernels add into the same float from
threads in different warps (constraint forces into qfrc_constraint, the squared gradient norm,
and the Hessian's J'DJ terms, both in full and incrementally). Measured on the H100
(experiments/scripts/det_probe.py): with Warp's deterministic atomics on exactly these four, runs are
bit-identical; on any fewer, they are not. Warp cannot record those atomics into a plan, so the
kernels below compute the same sums in a fixed order instead, each addend owned by one thread:

- qfrc_constraint: one warp per world takes the rows in row order, its lanes splitting each
  row's nonzeros (distinct dofs) with a warp barrier between rows;
- gradient: every thread writes its dof's gradient, thread 0 of the world sums the squares;
- Hessian (full and incremental): one warp per world takes the rows (or Newton blocks) in row
  order, its lanes splitting each row's entries (distinct Hessian entries) with a warp barrier
  between rows, so every entry receives its terms in row order.

`install()` swaps them in for MuJoCo Warp's kernel factories (same launch arguments). Pyramidal
cones and sparse Jacobians only (the humanoid's physics); other settings raise.
"""

from __future__ import annotations

import functools

import warp as wp
from mujoco_warp._src import solver, types

# Lanes per world in MuJoCo Warp's Hessian kernels (their third launch dimension).
LANES = wp.constant(solver._JTDAJ_THREADS_PER_GROUP)


@wp.func_native(snippet="""
#if defined(__CUDA_ARCH__)
__syncwarp();
#endif
""")
def _sync_lanes():
    """The LANES lanes of a world are one warp (the launch's last dimension): each sees the
    others' writes from before the barrier. On the CPU threads run one after another."""
    pass


@functools.cache
def qfrc_constraint_sparse(compact: bool, nv: int = 0, deterministic: bool = False):
    """Replaces solver._update_constraint_init_qfrc_constraint_sparse (launched (nworld, njmax)).

    The launch's threads are regrouped into one warp per world (flat thread index / LANES; njmax
    >= LANES gives enough, physics.py checks it): the rows one after another, the lanes
    splitting a row's nonzeros (distinct dofs), a warp barrier between rows."""
    COMPACT = compact

    @wp.kernel(module="unique", enable_backward=False, grid_stride=True)
    def kernel(
        nefc_in: wp.array(dtype=int),
        efc_J_rownnz_in: wp.array2d(dtype=int),
        efc_J_rowadr_in: wp.array2d(dtype=int),
        efc_J_colind_in: wp.array3d(dtype=int),
        efc_J_in: wp.array3d(dtype=float),
        efc_force_in: wp.array2d(dtype=float),
        dof_cdof_in: wp.array2d(dtype=int),
        state_changed_count_in: wp.array(dtype=int),
        ctx_done_in: wp.array(dtype=bool),
        qfrc_constraint_out: wp.array2d(dtype=float),
    ):
        launch_world, launch_row = wp.tid()
        njmax = efc_J_rownnz_in.shape[1]
        flat = launch_world * njmax + launch_row
        worldid = flat / LANES
        lane = flat - worldid * LANES
        if worldid >= nefc_in.shape[0]:
            return
        if ctx_done_in[worldid]:
            return
        if state_changed_count_in[worldid] == 0:
            return
        nefc = wp.min(nefc_in[worldid], njmax)
        for efcid in range(nefc):
            force = efc_force_in[worldid, efcid]
            if force != 0.0:
                rowadr = efc_J_rowadr_in[worldid, efcid]
                for i in range(lane, efc_J_rownnz_in[worldid, efcid], LANES):
                    colind = efc_J_colind_in[worldid, 0, rowadr + i]
                    if wp.static(COMPACT):
                        colind = dof_cdof_in[worldid, colind]
                    if colind >= 0:
                        value = efc_J_in[worldid, 0, rowadr + i] * force
                        qfrc_constraint_out[worldid, colind] = qfrc_constraint_out[worldid, colind] + value
            _sync_lanes()

    return kernel


@functools.cache
def gradient(stable_fast: bool, deterministic: bool = False):
    """Replaces solver._update_gradient_grad (launched (nworld, nv))."""
    STABLE_FAST = stable_fast

    @wp.kernel(module="unique", enable_backward=False, grid_stride=False)
    def kernel(
        qfrc_smooth_in: wp.array2d(dtype=float),
        qfrc_constraint_in: wp.array2d(dtype=float),
        efc_Ma_in: wp.array2d(dtype=float),
        state_changed_count_in: wp.array(dtype=int),
        ctx_done_in: wp.array(dtype=bool),
        ctx_grad_out: wp.array2d(dtype=float),
        ctx_grad_dot_out: wp.array(dtype=float),
    ):
        worldid, dofid = wp.tid()
        if ctx_done_in[worldid]:
            return
        if wp.static(STABLE_FAST):
            if state_changed_count_in[worldid] == 0:
                return
        grad = efc_Ma_in[worldid, dofid] - qfrc_smooth_in[worldid, dofid] - qfrc_constraint_in[worldid, dofid]
        ctx_grad_out[worldid, dofid] = grad
        if dofid == 0:
            # The same expression for every dof, summed in dof order by one thread.
            total = float(0.0)
            for i in range(ctx_grad_out.shape[1]):
                g = efc_Ma_in[worldid, i] - qfrc_smooth_in[worldid, i] - qfrc_constraint_in[worldid, i]
                total += g * g
            ctx_grad_dot_out[worldid] = ctx_grad_dot_out[worldid] + total

    return kernel


@functools.cache
def hessian_incremental_sparse(compact: bool, max_records: int = 0, deterministic: bool = False):
    """Replaces solver._update_gradient_h_incremental_sparse (launched (nworld, slots, LANES))."""
    COMPACT = compact

    @wp.kernel(module="unique", enable_backward=False, grid_stride=False)
    def kernel(
        efc_J_rownnz_in: wp.array2d(dtype=int),
        efc_J_rowadr_in: wp.array2d(dtype=int),
        efc_J_colind_in: wp.array3d(dtype=int),
        efc_J_in: wp.array3d(dtype=float),
        efc_D_in: wp.array2d(dtype=float),
        efc_state_in: wp.array2d(dtype=int),
        dof_cdof_in: wp.array2d(dtype=int),
        quad_changed_ids_in: wp.array2d(dtype=int),
        quad_changed_count_in: wp.array(dtype=int),
        slots_per_world: int,
        ctx_h_out: wp.array3d(dtype=float),
    ):
        worldid, slot, lane = wp.tid()
        # One warp per world (slot 0) takes the changed rows one after another, its lanes
        # splitting a row's entries as MuJoCo Warp's kernel does; a row's entries are distinct
        # Hessian entries, so no two lanes write one entry between barriers.
        if slot != 0:
            return
        n_changes = quad_changed_count_in[worldid]
        # The changed rows arrive in atomic order: take them in increasing row id instead.
        last = int(-1)
        for _ in range(n_changes):
            efcid = int(2147483647)
            for k in range(n_changes):
                candidate = quad_changed_ids_in[worldid, k]
                if candidate > last and candidate < efcid:
                    efcid = candidate
            last = efcid
            D = efc_D_in[worldid, efcid]
            sign = -D
            if efc_state_in[worldid, efcid] == types.ConstraintState.QUADRATIC.value:
                sign = D
            rownnz = efc_J_rownnz_in[worldid, efcid]
            rowadr = efc_J_rowadr_in[worldid, efcid]
            n_entries = rownnz * (rownnz + 1) // 2
            for entry in range(lane, n_entries, LANES):
                ii = int((wp.sqrt(float(8 * entry + 1)) - 1.0) * 0.5)
                jj = entry - ii * (ii + 1) // 2
                h = sign * efc_J_in[worldid, 0, rowadr + ii] * efc_J_in[worldid, 0, rowadr + jj]
                if h != 0.0:
                    colindi = efc_J_colind_in[worldid, 0, rowadr + ii]
                    colindj = efc_J_colind_in[worldid, 0, rowadr + jj]
                    skip = False
                    if wp.static(COMPACT):
                        colindi = dof_cdof_in[worldid, colindi]
                        colindj = dof_cdof_in[worldid, colindj]
                        skip = colindi < 0 or colindj < 0
                    if not skip:
                        r = wp.min(colindi, colindj)
                        c = wp.max(colindi, colindj)
                        ctx_h_out[worldid, r, c] = ctx_h_out[worldid, r, c] + h
            _sync_lanes()

    return kernel


@functools.cache
def hessian_sparse(
    compact: bool,
    cone_type,
    max_condim: int,
    block_dim: int = types.BlockDim.update_gradient_JTDAJ_sparse,
    max_records: int = 0,
    deterministic: bool = False,
):
    """Replaces solver._JTDACJ_sparse (launched (nworld, groups_per_world, LANES))."""
    if cone_type == types.ConeType.ELLIPTIC:
        raise NotImplementedError(
            "deterministic physics supports pyramidal cones only (set cone = \"pyramidal\" or deterministic = false)"
        )
    if block_dim % LANES != 0:
        raise NotImplementedError(f"the Hessian kernel needs whole warps per block, got block_dim {block_dim}")
    COMPACT = compact

    @wp.kernel(module="unique", enable_backward=False, grid_stride=True, module_options={"block_dim": block_dim})
    def kernel(
        opt_impratio_invsqrt: wp.array(dtype=float),
        contact_friction_in: wp.array(dtype=types.vec5),
        contact_dim_in: wp.array(dtype=int),
        efc_id_in: wp.array2d(dtype=int),
        efc_jtdaj_adr_in: wp.array2d(dtype=int),
        efc_jtdaj_nrow_in: wp.array2d(dtype=int),
        efc_jtdaj_nblock_in: wp.array(dtype=int),
        efc_J_rownnz_in: wp.array2d(dtype=int),
        efc_J_rowadr_in: wp.array2d(dtype=int),
        efc_J_colind_in: wp.array3d(dtype=int),
        efc_J_in: wp.array3d(dtype=float),
        efc_D_in: wp.array2d(dtype=float),
        efc_state_in: wp.array2d(dtype=int),
        dof_cdof_in: wp.array2d(dtype=int),
        ctx_Jaref_in: wp.array2d(dtype=float),
        ctx_done_in: wp.array(dtype=bool),
        groups_per_world: int,
        h_out: wp.array3d(dtype=float),
    ):
        worldid, slot, lane = wp.tid()
        # As hessian_incremental_sparse: one warp per world, blocks one after another (they
        # are in row order: determinism.sort_constraints lists them so).
        if slot != 0:
            return
        if ctx_done_in[worldid]:
            return
        for groupid in range(efc_jtdaj_nblock_in[worldid]):
            head_row = efc_jtdaj_adr_in[worldid, groupid]
            block_rows = efc_jtdaj_nrow_in[worldid, groupid]
            head_adr = efc_J_rowadr_in[worldid, head_row]
            support = efc_J_rownnz_in[worldid, head_row]
            n_entries = support * (support + 1) // 2
            for entry in range(lane, n_entries, LANES):
                block_col = int((wp.sqrt(float(8 * entry + 1)) - 1.0) * 0.5)
                block_row = entry - block_col * (block_col + 1) // 2
                dof_row = efc_J_colind_in[worldid, 0, head_adr + block_row]
                dof_col = efc_J_colind_in[worldid, 0, head_adr + block_col]
                hval = float(0.0)
                for member in range(block_rows):
                    member_row = head_row + member
                    if efc_state_in[worldid, member_row] == types.ConstraintState.QUADRATIC.value:
                        member_adr = efc_J_rowadr_in[worldid, member_row]
                        j_row = efc_J_in[worldid, 0, member_adr + block_row]
                        j_col = efc_J_in[worldid, 0, member_adr + block_col]
                        hval += j_row * efc_D_in[worldid, member_row] * j_col
                skip = hval == 0.0
                if wp.static(COMPACT):
                    dof_row = dof_cdof_in[worldid, dof_row]
                    dof_col = dof_cdof_in[worldid, dof_col]
                    skip = skip or dof_row < 0 or dof_col < 0
                if not skip:
                    r = wp.min(dof_row, dof_col)
                    c = wp.max(dof_row, dof_col)
                    h_out[worldid, r, c] = h_out[worldid, r, c] + hval
            _sync_lanes()

    return kernel


def install():
    """Swaps the kernels above in for MuJoCo Warp's (the launches are unchanged)."""
    solver._update_constraint_init_qfrc_constraint_sparse = qfrc_constraint_sparse
    solver._update_gradient_grad = gradient
    solver._update_gradient_h_incremental_sparse = hessian_incremental_sparse
    solver._JTDACJ_sparse = hessian_sparse
