"""The deterministic physics variant on Warp's CPU device (determinism.py, deterministic_solver.py).

1. The contact sort puts shuffled synthetic contacts (several worlds, several contacts per geom
   pair) into (world, geom pair, i-th contact) order, and every field follows its contact.
2. One MuJoCo Warp step of the humanoid on the floor, with and without the deterministic
   variant: on the CPU device threads run in order, so MuJoCo Warp's own sums already come in
   row order and the two must agree bit for bit (the replacement kernels compute the same sums);
   the variant's contacts are in canonical order, its constraint rows sorted by (type, id) with
   their Jacobian rows packed, and each contact's rows and the Newton blocks point back
   correctly.
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


def humanoid_step():
    nworld = 8
    plain = step(False, nworld)
    det = step(True, nworld)
    for name in ("qpos", "qvel", "qacc"):
        a, b = getattr(plain, name).numpy(), getattr(det, name).numpy()
        check(f"step: {name} as MuJoCo Warp's", bool((a == b).all()), f"max |diff| {np.abs(a - b).max():.3g}")
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


contact_sort()
humanoid_step()
print(f"{'FAILED: ' + ', '.join(failures) if failures else 'all determinism checks passed'}")
sys.exit(1 if failures else 0)
