"""The deterministic physics variant on Warp's CPU device (determinism.py, deterministic_solver.py).

1. The contact sort puts shuffled synthetic contacts (several worlds, several contacts per geom
   pair) into (world, geom pair, i-th contact) order, and every field follows its contact.
2. One MuJoCo Warp step of the humanoid on the floor, with and without the deterministic
   variant: on the CPU device threads run in order, so MuJoCo Warp's own sums already come in
   row order and the two must agree bit for bit (the replacement kernels compute the same sums);
   the variant's contacts are in canonical order, its constraint rows sorted by (type, id) with
   their Jacobian rows packed, and each contact's rows and the Newton blocks point back
   correctly.
3. The same step with contacts and constraint rows shuffled before each sort (as GPU atomics
   leave them) gives the same bits: the sorts undo any order.
4. A deterministic physics config with an elliptic cone or njmax < 32 is refused at load.
Prints one line per check; exits non-zero if any fails (tests/physics_determinism_cpu.rs).
"""

from __future__ import annotations

import sys
from types import SimpleNamespace

from check_support import DEVICE, np, physics, wp

import determinism  # noqa: E402
import physics_reference  # noqa: E402

failures = []


def check(name: str, ok: bool, detail: str = ""):
    print(f"{name}: {detail} {'ok' if ok else 'FAIL'}".replace("  ", " "))
    if not ok:
        failures.append(name)


def contact_sort():
    rng = np.random.default_rng(3)
    nworld, naconmax = 6, 96
    # Up to three contacts per (world, pair), found in a random order.
    keys = [(w, g0, g1, i) for w in range(nworld) for g0 in range(3) for g1 in range(3, 5) for i in range(rng.integers(0, 4))]
    rng.shuffle(keys)
    keys = np.array(keys, dtype=np.int32)
    n = len(keys)

    def arr(x, dtype):
        full = np.zeros((naconmax,) + x.shape[1:], x.dtype)
        full[:n] = x
        return wp.array(full, dtype=dtype, device=DEVICE)

    dist = rng.normal(size=n).astype(np.float32)
    pos = rng.normal(size=(n, 3)).astype(np.float32)
    c = SimpleNamespace(
        worldid=arr(keys[:, 0], int), geom=arr(keys[:, 1:3].copy(), wp.vec2i), geomcollisionid=arr(keys[:, 3].copy(), int),
        flex=wp.empty(0, dtype=wp.vec2i, device=DEVICE), elem=wp.empty(0, dtype=wp.vec2i, device=DEVICE),
        vert=wp.empty(0, dtype=wp.vec2i, device=DEVICE), surfacevel=wp.empty(0, dtype=wp.vec3, device=DEVICE),
        dist=arr(dist, float), pos=arr(pos, wp.vec3), frame=arr(np.zeros((n, 3, 3), np.float32), wp.mat33),
        includemargin=arr(np.zeros(n, np.float32), float), friction=arr(np.zeros((n, 5), np.float32), determinism._vec5),
        solref=arr(np.zeros((n, 2), np.float32), wp.vec2), solreffriction=arr(np.zeros((n, 2), np.float32), wp.vec2),
        solimp=arr(np.zeros((n, 5), np.float32), determinism._vec5), dim=arr(np.full(n, 3, np.int32), int),
        type=arr(np.ones(n, np.int32), int), adhesion=arr(np.zeros(n, np.float32), float),
    )
    d = SimpleNamespace(nworld=nworld, naconmax=naconmax, nacon=wp.array([n], dtype=int, device=DEVICE), contact=c)
    with wp.ScopedDevice(DEVICE):
        determinism.sort_contacts(None, d)
    got = np.column_stack([c.worldid.numpy()[:n], c.geom.numpy()[:n], c.geomcollisionid.numpy()[:n]])
    order = np.lexsort((keys[:, 3], keys[:, 2], keys[:, 1], keys[:, 0]))
    check("contact sort: canonical order", bool((got == keys[order]).all()), f"{n} contacts in {nworld} worlds")
    check("contact sort: fields follow their contact",
          bool((c.dist.numpy()[:n] == dist[order]).all() and (c.pos.numpy()[:n] == pos[order]).all()))


def step(deterministic: bool, nworld: int):
    config = dict(physics.load_physics_config(physics.REPO / "configs/physics/default.toml"), deterministic=deterministic)
    import mujoco_warp as mjw

    with wp.ScopedDevice(DEVICE):
        mjm, m, d = physics.make_model_data(config, nworld)
        init = physics_reference.initial_state(mjm, nworld, "contact", 7)
        for name, value in zip(("qpos", "qvel", "ctrl"), init):
            wp.copy(getattr(d, name), wp.array(value, dtype=float))
        mjw.step(m, d)
    return d


def shuffle_contacts(d, rng):
    """Contacts in a random order, as GPU atomics might leave them."""
    n = int(d.nacon.numpy()[0])
    perm = rng.permutation(n)
    for name in determinism.CONTACT_FIELDS:
        field = getattr(d.contact, name)
        if field.shape[0] > 0:
            values = field.numpy().copy()
            values[:n] = values[perm]
            field.assign(values)


def shuffle_constraints(d, rng):
    """Each world's constraint rows in a random order of their (type, id) groups, Jacobian rows
    stored in yet another order, Newton blocks listed in random order, all references renumbered:
    a state the GPU's atomics could leave."""
    e, c = d.efc, d.contact
    cols = {name: getattr(e, name).numpy().copy() for name in ("type", "id", "J_rownnz", "J_rowadr", "pos", "margin",
                                                               "D", "vel", "aref", "frictionloss", "Jqvel")}
    colind, J = e.J_colind.numpy().copy(), e.J.numpy().copy()
    new_colind, new_J = colind.copy(), J.copy()
    address = c.efc_address.numpy().copy()
    worldid, nacon = c.worldid.numpy(), int(d.nacon.numpy()[0])
    nblock, badr, bnrow = e.jtdaj_nblock.numpy(), e.jtdaj_adr.numpy().copy(), e.jtdaj_nrow.numpy().copy()
    for w in range(d.nworld):
        n = int(d.nefc.numpy()[w])
        groups = []
        for r in range(n):
            if r and (cols["type"][w, r], cols["id"][w, r]) == (cols["type"][w, r - 1], cols["id"][w, r - 1]):
                groups[-1].append(r)
            else:
                groups.append([r])
        old = [r for g in rng.permutation(len(groups)) for r in groups[g]]
        new = np.empty(n, int)
        new[old] = np.arange(n)
        for values in cols.values():
            values[w, :n] = values[w, old]
        # Jacobian rows stored in reverse row order.
        adr = 0
        for k in reversed(range(n)):
            nnz, src = cols["J_rownnz"][w, k], cols["J_rowadr"][w, k]
            new_colind[w, 0, adr:adr + nnz] = colind[w, 0, src:src + nnz]
            new_J[w, 0, adr:adr + nnz] = J[w, 0, src:src + nnz]
            cols["J_rowadr"][w, k] = adr
            adr += nnz
        for con in range(nacon):
            if worldid[con] == w:
                address[con] = [new[r] if 0 <= r < n else r for r in address[con]]
        nb = int(nblock[w])
        order = rng.permutation(nb)
        badr[w, :nb], bnrow[w, :nb] = new[badr[w, :nb][order]], bnrow[w, :nb][order]
    for name, values in cols.items():
        getattr(e, name).assign(values)
    e.J_colind.assign(new_colind)
    e.J.assign(new_J)
    c.efc_address.assign(address)
    e.jtdaj_adr.assign(badr)
    e.jtdaj_nrow.assign(bnrow)


def humanoid_step():
    nworld = 8
    plain = step(False, nworld)
    det = step(True, nworld)
    for name in ("qpos", "qvel", "qacc"):
        a, b = getattr(plain, name).numpy(), getattr(det, name).numpy()
        check(f"step: {name} as MuJoCo Warp's", bool((a == b).all()), f"max |diff| {np.abs(a - b).max():.3g}")
    # The same step from contacts and rows in random orders: the sorts restore the canonical
    # order, so the result must not change by a bit.
    # (physics.make_model_data installs determinism.sort_contacts/sort_constraints as they are
    # when it runs.)
    rng = np.random.default_rng(11)
    sorts = determinism.sort_contacts, determinism.sort_constraints
    shuffles = []

    def contacts(m, d):
        shuffles.append("contacts")
        shuffle_contacts(d, rng)
        sorts[0](m, d)

    def constraints(m, d):
        shuffles.append("constraints")
        shuffle_constraints(d, rng)
        sorts[1](m, d)

    determinism.sort_contacts, determinism.sort_constraints = contacts, constraints
    try:
        shuffled = step(True, nworld)
    finally:
        determinism.sort_contacts, determinism.sort_constraints = sorts
    check("step from shuffled contacts and rows: both shuffles ran", shuffles == ["contacts", "constraints"],
          str(shuffles))
    for name in ("qpos", "qvel", "qacc"):
        a, b = getattr(det, name).numpy(), getattr(shuffled, name).numpy()
        check(f"step from shuffled contacts and rows: {name} unchanged", bool((a == b).all()),
              f"max |diff| {np.abs(a - b).max():.3g}")
    n = int(det.nacon.numpy()[0])
    w, g, i = det.contact.worldid.numpy()[:n], det.contact.geom.numpy()[:n], det.contact.geomcollisionid.numpy()[:n]
    check("step: contacts in canonical order", bool((np.lexsort((i, g[:, 1], g[:, 0], w)) == np.arange(n)).all()), f"{n} contacts")
    nefc, etype, eid = det.nefc.numpy(), det.efc.type.numpy(), det.efc.id.numpy()
    rownnz, rowadr = det.efc.J_rownnz.numpy(), det.efc.J_rowadr.numpy()
    rows_ok = packed = True
    for world in range(nworld):
        k = nefc[world]
        rows_ok &= all((etype[world, r], eid[world, r]) <= (etype[world, r + 1], eid[world, r + 1]) for r in range(k - 1))
        packed &= bool((rowadr[world, :k] == np.concatenate([[0], np.cumsum(rownnz[world, :k])[:-1]])).all())
    check("step: constraint rows by (type, id)", rows_ok, f"{nefc.sum()} rows")
    check("step: Jacobian rows packed in row order", packed)
    address = det.contact.efc_address.numpy()[:n]
    back = all(eid[w[c], r] == c for c in range(n) for r in address[c] if r >= 0)
    check("step: contacts' rows point back at them", back)
    nblock, badr = det.efc.jtdaj_nblock.numpy(), det.efc.jtdaj_adr.numpy()
    check("step: Newton blocks in row order", all((np.diff(badr[world, :nblock[world]]) > 0).all() for world in range(nworld)))


def config_validation():
    """The variant's limits are refused when the physics config is read, naming the key."""
    import tempfile

    text = (physics.REPO / "configs/physics/deterministic.toml").read_text()
    for key, old, new in (("cone", 'cone = "pyramidal"', 'cone = "elliptic"'), ("njmax", "njmax = 200", "njmax = 16")):
        assert old in text, old
        with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
            f.write(text.replace(old, new))
        try:
            physics.load_physics_config(f.name)
            message = "accepted"
        except physics.ConfigError as e:
            message = str(e)
        check(f"config: deterministic with {new} refused", f"`{key}`" in message, message)


config_validation()
contact_sort()
humanoid_step()
print(f"{'FAILED: ' + ', '.join(failures) if failures else 'all determinism checks passed'}")
sys.exit(1 if failures else 0)
