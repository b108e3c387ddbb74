"""Stable contact order and canonical constraint rows for MuJoCo Warp 4.0.

MuJoCo Warp collects contacts and constraint rows with atomic counters, so their order (and with
it the order of every sum over them) changes from run to run: the same state and controls give
qvel that differ by ~1e-4 after one step with contacts. MuJoCo Warp 4.0 has the hooks for a fix
(`DeterminismType.CONTACTS` and `.CONSTRAINT` call `collision_driver._sort_contacts` and
`constraint._sort_constraints`) but both are empty stubs, and its third feature (`.ATOMICS`,
Warp's deterministic atomics) cannot be recorded into a plan. `install()` fills the two stubs
with the kernels below: plain Warp kernels with integer atomics only, so APIC records them and the
Rust runtime replays them like any other MuJoCo Warp kernel.

Contacts are ordered by (world, geom pair, flex/element/vertex ids, i-th contact of the pair), a
key that does not depend on which thread found the contact first. Constraint rows are ordered per
world by (type, id, row) after the contact sort, so each contact's rows stay contiguous and in
dimension order; their sparse Jacobian rows are repacked in that order, and the contacts'
`efc_address` and the Newton solver's JTDAJ blocks are renumbered to match.
"""

from __future__ import annotations

import warp as wp
from mujoco_warp._src import types

# Contacts per world that the contact sort handles (the humanoid has at most 47; see
# configs/physics/default.toml). A world with more leaves every contact in its found order.
MAX_WORLD_CONTACTS = 128
# Worlds per chunk in the two-level prefix sum over per-world contact counts.
WORLD_CHUNK = wp.constant(256)

_vec5 = types.vec5


@wp.kernel(module="unique", enable_backward=False)
def _contact_bucket(
    naconmax: int,
    nacon: wp.array(dtype=int),
    worldid: wp.array(dtype=int),
    world_ncon: wp.array(dtype=int),
    world_contacts: wp.array2d(dtype=int),
):
    conid = wp.tid()
    if conid >= wp.min(nacon[0], naconmax):
        return
    w = worldid[conid]
    slot = wp.atomic_add(world_ncon, w, 1)
    if slot < world_contacts.shape[1]:
        world_contacts[w, slot] = conid


@wp.kernel(module="unique", enable_backward=False)
def _contact_chunk_sums(nworld: int, world_ncon: wp.array(dtype=int), chunk_sums: wp.array(dtype=int)):
    chunk = wp.tid()
    total = int(0)
    for w in range(chunk * WORLD_CHUNK, wp.min(nworld, (chunk + 1) * WORLD_CHUNK)):
        total += world_ncon[w]
    chunk_sums[chunk] = total


@wp.func
def _contact_before(
    geom: wp.array(dtype=wp.vec2i),
    flex: wp.array(dtype=wp.vec2i),
    elem: wp.array(dtype=wp.vec2i),
    vert: wp.array(dtype=wp.vec2i),
    geomcollisionid: wp.array(dtype=int),
    a: int,
    b: int,
) -> bool:
    """Whether contact a sorts before contact b of the same world (ties: found order)."""
    ka = geom[a]
    kb = geom[b]
    for k in range(2):
        if ka[k] != kb[k]:
            return ka[k] < kb[k]
    # flex, elem and vert are empty arrays when the model has no flexes.
    if flex.shape[0] > 0:
        ka = flex[a]
        kb = flex[b]
        for k in range(2):
            if ka[k] != kb[k]:
                return ka[k] < kb[k]
        ka = elem[a]
        kb = elem[b]
        for k in range(2):
            if ka[k] != kb[k]:
                return ka[k] < kb[k]
        ka = vert[a]
        kb = vert[b]
        for k in range(2):
            if ka[k] != kb[k]:
                return ka[k] < kb[k]
    ia = geomcollisionid[a]
    ib = geomcollisionid[b]
    if ia != ib:
        return ia < ib
    return a < b


@wp.kernel(module="unique", enable_backward=False)
def _contact_order(
    nworld: int,
    world_ncon: wp.array(dtype=int),
    world_contacts: wp.array2d(dtype=int),
    chunk_sums: wp.array(dtype=int),
    geom: wp.array(dtype=wp.vec2i),
    flex: wp.array(dtype=wp.vec2i),
    elem: wp.array(dtype=wp.vec2i),
    vert: wp.array(dtype=wp.vec2i),
    geomcollisionid: wp.array(dtype=int),
    unsorted: wp.array(dtype=int),
    order: wp.array(dtype=int),
):
    w, slot = wp.tid()
    n = world_ncon[w]
    if slot >= n:
        return
    if n > world_contacts.shape[1]:
        # Too many contacts in this world to sort: keep the found order everywhere.
        unsorted[0] = 1
        return
    conid = world_contacts[w, slot]
    # Contacts of earlier worlds come first: whole chunks, then this chunk's earlier worlds.
    offset = int(0)
    chunk = w / WORLD_CHUNK
    for c in range(chunk):
        offset += chunk_sums[c]
    for v in range(chunk * WORLD_CHUNK, w):
        offset += world_ncon[v]
    rank = int(0)
    for other in range(n):
        if other != slot:
            if _contact_before(geom, flex, elem, vert, geomcollisionid, world_contacts[w, other], conid):
                rank += 1
    order[offset + rank] = conid


@wp.kernel(module="unique", enable_backward=False)
def _contact_gather(
    naconmax: int,
    nacon: wp.array(dtype=int),
    unsorted: wp.array(dtype=int),
    order: wp.array(dtype=int),
    # In:
    dist_in: wp.array(dtype=float),
    pos_in: wp.array(dtype=wp.vec3),
    frame_in: wp.array(dtype=wp.mat33),
    includemargin_in: wp.array(dtype=float),
    friction_in: wp.array(dtype=_vec5),
    solref_in: wp.array(dtype=wp.vec2),
    solreffriction_in: wp.array(dtype=wp.vec2),
    solimp_in: wp.array(dtype=_vec5),
    dim_in: wp.array(dtype=int),
    geom_in: wp.array(dtype=wp.vec2i),
    flex_in: wp.array(dtype=wp.vec2i),
    elem_in: wp.array(dtype=wp.vec2i),
    vert_in: wp.array(dtype=wp.vec2i),
    worldid_in: wp.array(dtype=int),
    type_in: wp.array(dtype=int),
    geomcollisionid_in: wp.array(dtype=int),
    adhesion_in: wp.array(dtype=float),
    surfacevel_in: wp.array(dtype=wp.vec3),
    # Out:
    dist_out: wp.array(dtype=float),
    pos_out: wp.array(dtype=wp.vec3),
    frame_out: wp.array(dtype=wp.mat33),
    includemargin_out: wp.array(dtype=float),
    friction_out: wp.array(dtype=_vec5),
    solref_out: wp.array(dtype=wp.vec2),
    solreffriction_out: wp.array(dtype=wp.vec2),
    solimp_out: wp.array(dtype=_vec5),
    dim_out: wp.array(dtype=int),
    geom_out: wp.array(dtype=wp.vec2i),
    flex_out: wp.array(dtype=wp.vec2i),
    elem_out: wp.array(dtype=wp.vec2i),
    vert_out: wp.array(dtype=wp.vec2i),
    worldid_out: wp.array(dtype=int),
    type_out: wp.array(dtype=int),
    geomcollisionid_out: wp.array(dtype=int),
    adhesion_out: wp.array(dtype=float),
    surfacevel_out: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    if i >= wp.min(nacon[0], naconmax):
        return
    src = i
    if unsorted[0] == 0:
        src = order[i]
    dist_out[i] = dist_in[src]
    pos_out[i] = pos_in[src]
    frame_out[i] = frame_in[src]
    includemargin_out[i] = includemargin_in[src]
    friction_out[i] = friction_in[src]
    solref_out[i] = solref_in[src]
    solreffriction_out[i] = solreffriction_in[src]
    solimp_out[i] = solimp_in[src]
    dim_out[i] = dim_in[src]
    geom_out[i] = geom_in[src]
    if flex_in.shape[0] > 0:
        flex_out[i] = flex_in[src]
        elem_out[i] = elem_in[src]
        vert_out[i] = vert_in[src]
    worldid_out[i] = worldid_in[src]
    type_out[i] = type_in[src]
    geomcollisionid_out[i] = geomcollisionid_in[src]
    adhesion_out[i] = adhesion_in[src]
    if surfacevel_in.shape[0] > 0:
        surfacevel_out[i] = surfacevel_in[src]


CONTACT_FIELDS = (
    "dist", "pos", "frame", "includemargin", "friction", "solref", "solreffriction", "solimp", "dim",
    "geom", "flex", "elem", "vert", "worldid", "type", "geomcollisionid", "adhesion", "surfacevel",
)


def sort_contacts(m, d):
    """Reorders d.contact into the canonical order (fills MuJoCo Warp's `_sort_contacts`)."""
    nworld = d.nworld
    nchunk = (nworld + WORLD_CHUNK - 1) // WORLD_CHUNK
    world_ncon = wp.zeros(nworld, dtype=int)
    world_contacts = wp.empty((nworld, MAX_WORLD_CONTACTS), dtype=int)
    chunk_sums = wp.empty(nchunk, dtype=int)
    unsorted = wp.zeros(1, dtype=int)
    order = wp.empty(d.naconmax, dtype=int)
    c = d.contact
    wp.launch(_contact_bucket, dim=d.naconmax, inputs=[d.naconmax, d.nacon, c.worldid], outputs=[world_ncon, world_contacts])
    wp.launch(_contact_chunk_sums, dim=nchunk, inputs=[nworld, world_ncon], outputs=[chunk_sums])
    wp.launch(
        _contact_order,
        dim=(nworld, MAX_WORLD_CONTACTS),
        inputs=[nworld, world_ncon, world_contacts, chunk_sums, c.geom, c.flex, c.elem, c.vert, c.geomcollisionid],
        outputs=[unsorted, order],
    )
    fields = [getattr(c, name) for name in CONTACT_FIELDS]
    sorted_fields = [wp.empty_like(f) for f in fields]
    wp.launch(_contact_gather, dim=d.naconmax, inputs=[d.naconmax, d.nacon, unsorted, order, *fields], outputs=sorted_fields)
    # Back into d.contact, only the first nacon entries: the same kernel with the "unsorted" flag
    # set is a plain copy (cheaper than whole-array copies of naconmax entries).
    copy = wp.ones(1, dtype=int)
    wp.launch(_contact_gather, dim=d.naconmax, inputs=[d.naconmax, d.nacon, copy, order, *sorted_fields], outputs=fields)


# ---- constraint rows ---------------------------------------------------------------------------


@wp.kernel(module="unique", enable_backward=False)
def _efc_order(
    njmax: int,
    nefc: wp.array(dtype=int),
    efc_type: wp.array2d(dtype=int),
    efc_id: wp.array2d(dtype=int),
    new_row: wp.array2d(dtype=int),
    old_row: wp.array2d(dtype=int),
):
    w, row = wp.tid()
    n = wp.min(nefc[w], njmax)
    if row >= n:
        return
    t = efc_type[w, row]
    i = efc_id[w, row]
    rank = int(0)
    for other in range(n):
        to = efc_type[w, other]
        io = efc_id[w, other]
        if to < t or (to == t and (io < i or (io == i and other < row))):
            rank += 1
    new_row[w, row] = rank
    old_row[w, rank] = row


@wp.kernel(module="unique", enable_backward=False)
def _efc_gather(
    njmax: int,
    nefc: wp.array(dtype=int),
    old_row: wp.array2d(dtype=int),
    copy: int,
    type_in: wp.array2d(dtype=int),
    id_in: wp.array2d(dtype=int),
    rownnz_in: wp.array2d(dtype=int),
    rowadr_in: wp.array2d(dtype=int),
    colind_in: wp.array3d(dtype=int),
    J_in: wp.array3d(dtype=float),
    pos_in: wp.array2d(dtype=float),
    margin_in: wp.array2d(dtype=float),
    D_in: wp.array2d(dtype=float),
    vel_in: wp.array2d(dtype=float),
    aref_in: wp.array2d(dtype=float),
    frictionloss_in: wp.array2d(dtype=float),
    Jqvel_in: wp.array2d(dtype=float),
    type_out: wp.array2d(dtype=int),
    id_out: wp.array2d(dtype=int),
    rownnz_out: wp.array2d(dtype=int),
    rowadr_out: wp.array2d(dtype=int),
    colind_out: wp.array3d(dtype=int),
    J_out: wp.array3d(dtype=float),
    pos_out: wp.array2d(dtype=float),
    margin_out: wp.array2d(dtype=float),
    D_out: wp.array2d(dtype=float),
    vel_out: wp.array2d(dtype=float),
    aref_out: wp.array2d(dtype=float),
    frictionloss_out: wp.array2d(dtype=float),
    Jqvel_out: wp.array2d(dtype=float),
):
    """Row k of the canonical order from row old_row[k], Jacobian rows packed in that order; with
    `copy` set, row k from row k (the packed rows back into d.efc)."""
    w, k = wp.tid()
    n = wp.min(nefc[w], njmax)
    if k >= n:
        return
    src = k
    if copy == 0:
        src = old_row[w, k]
    adr = int(0)
    for j in range(k):
        if copy == 0:
            adr += rownnz_in[w, old_row[w, j]]
        else:
            adr += rownnz_in[w, j]
    nnz = rownnz_in[w, src]
    src_adr = rowadr_in[w, src]
    for t in range(nnz):
        colind_out[w, 0, adr + t] = colind_in[w, 0, src_adr + t]
        J_out[w, 0, adr + t] = J_in[w, 0, src_adr + t]
    type_out[w, k] = type_in[w, src]
    id_out[w, k] = id_in[w, src]
    rownnz_out[w, k] = nnz
    rowadr_out[w, k] = adr
    pos_out[w, k] = pos_in[w, src]
    margin_out[w, k] = margin_in[w, src]
    D_out[w, k] = D_in[w, src]
    vel_out[w, k] = vel_in[w, src]
    aref_out[w, k] = aref_in[w, src]
    frictionloss_out[w, k] = frictionloss_in[w, src]
    Jqvel_out[w, k] = Jqvel_in[w, src]


@wp.kernel(module="unique", enable_backward=False)
def _efc_renumber_contacts(
    naconmax: int,
    njmax: int,
    nacon: wp.array(dtype=int),
    worldid: wp.array(dtype=int),
    new_row: wp.array2d(dtype=int),
    efc_address: wp.array2d(dtype=int),
):
    conid, k = wp.tid()
    if conid >= wp.min(nacon[0], naconmax):
        return
    row = efc_address[conid, k]
    if row >= 0 and row < njmax:
        efc_address[conid, k] = new_row[worldid[conid], row]


@wp.kernel(module="unique", enable_backward=False)
def _efc_renumber_blocks(
    njmax: int,
    nblock: wp.array(dtype=int),
    new_row: wp.array2d(dtype=int),
    copy: int,
    adr_in: wp.array2d(dtype=int),
    nrow_in: wp.array2d(dtype=int),
    adr_out: wp.array2d(dtype=int),
    nrow_out: wp.array2d(dtype=int),
):
    """JTDAJ blocks (first row, row count) renumbered and listed in row order; with `copy` set,
    copied as they are (back into d.efc)."""
    w, b = wp.tid()
    n = wp.min(nblock[w], njmax)
    if b >= n:
        return
    first = adr_in[w, b]
    if copy == 0:
        first = new_row[w, first]
    rank = int(0)
    for other in range(n):
        first_other = adr_in[w, other]
        if copy == 0:
            first_other = new_row[w, first_other]
        if first_other < first:
            rank += 1
    adr_out[w, rank] = first
    nrow_out[w, rank] = nrow_in[w, b]


EFC_ROW_FIELDS = ("type", "id", "J_rownnz", "J_rowadr")
EFC_VALUE_FIELDS = ("pos", "margin", "D", "vel", "aref", "frictionloss", "Jqvel")


def sort_constraints(m, d):
    """Reorders d.efc rows canonically per world (fills MuJoCo Warp's `_sort_constraints`)."""
    if not m.is_sparse:
        raise NotImplementedError(
            "the canonical constraint order supports sparse Jacobians only; this model is dense "
            "(set deterministic = false in the physics config)"
        )
    e = d.efc
    njmax = d.njmax
    shape = (d.nworld, njmax)
    new_row = wp.empty(shape, dtype=int)
    old_row = wp.empty(shape, dtype=int)
    wp.launch(_efc_order, dim=shape, inputs=[njmax, d.nefc, e.type, e.id], outputs=[new_row, old_row])

    rows = [getattr(e, f) for f in EFC_ROW_FIELDS]
    values = [getattr(e, f) for f in EFC_VALUE_FIELDS]
    rows_tmp = [wp.empty(shape, dtype=int) for _ in rows]
    values_tmp = [wp.empty(shape, dtype=float) for _ in values]
    colind_tmp = wp.empty_like(e.J_colind)
    J_tmp = wp.empty_like(e.J)
    for copy, src, dst in (
        (0, (rows, e.J_colind, e.J, values), (rows_tmp, colind_tmp, J_tmp, values_tmp)),
        (1, (rows_tmp, colind_tmp, J_tmp, values_tmp), (rows, e.J_colind, e.J, values)),
    ):
        wp.launch(
            _efc_gather,
            dim=shape,
            inputs=[njmax, d.nefc, old_row, copy, *src[0], src[1], src[2], *src[3]],
            outputs=[*dst[0], dst[1], dst[2], *dst[3]],
        )
    c = d.contact
    wp.launch(
        _efc_renumber_contacts,
        dim=(d.naconmax, c.efc_address.shape[1]),
        inputs=[d.naconmax, njmax, d.nacon, c.worldid, new_row],
        outputs=[c.efc_address],
    )
    if m.opt.solver == types.SolverType.NEWTON:  # its JTDAJ blocks name rows
        adr_tmp = wp.empty(shape, dtype=int)
        nrow_tmp = wp.empty(shape, dtype=int)
        for copy, src, dst in ((0, (e.jtdaj_adr, e.jtdaj_nrow), (adr_tmp, nrow_tmp)),
                               (1, (adr_tmp, nrow_tmp), (e.jtdaj_adr, e.jtdaj_nrow))):
            wp.launch(
                _efc_renumber_blocks,
                dim=shape,
                inputs=[njmax, e.jtdaj_nblock, new_row, copy, *src],
                outputs=list(dst),
            )


def install():
    """Fills MuJoCo Warp's empty determinism hooks with the kernels above."""
    from mujoco_warp._src import collision_driver, constraint

    collision_driver._sort_contacts = sort_contacts
    constraint._sort_constraints = sort_constraints
