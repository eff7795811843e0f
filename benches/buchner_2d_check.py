#!/usr/bin/env python3
"""A second, independent two-dimensional weakly compressible SPH of the `buchner_p1` tank.

It shares no code with wgsph: it exists to tell whether the first impact that wgsph's
three-dimensional slab computes at Buchner's P1 (docs/validation.md) is what the equations give
in two dimensions too. Deliberately small and plain: one file, numpy and numba, one thread.

The model (the settings of Marrone et al. 2011's delta-SPH where wgsph has an equivalent):
  - continuity density (report Eq. for d rho/dt) with the delta-SPH diffusive term of Molteni &
    Colagrossi (2009), its hydrostatic density difference removed (Fourtakas et al. 2019);
  - a linear equation of state p = c0^2 (rho - rho0) (or Tait with --tait), negative pressure
    kept unless --clamp;
  - the symmetric pressure force, Monaghan's artificial viscosity on approaching fluid pairs
    (alpha, beta = 0), or Morris et al.'s (1997) Laplacian viscosity with nu = a h c0 / 8;
  - dummy wall particles whose pressure is extrapolated from the fluid with the hydrostatic
    term (Adami, Hu & Adams 2012), free-slip (no viscosity with them);
  - the cubic spline, h = 2 spacings; symplectic Euler: the velocity first, then the density
    rate from the new velocity, then the positions (updating the density from the old velocity
    is forward Euler for the sound waves and grows without bound);
  - the column H = 0.6 m by 2H at the back of a tank 3.22 m long whose side walls reach 2.4 m
    (no lid), started at hydrostatic density.

Output: a CSV of the time (s) and the fluid's pressure (Pa) on the far wall at heights 0, 0.01,
..., 0.20 m, each a Shepard-normalised kernel average of the fluid particles within 2h, every
0.5 ms.

    pip install numpy numba
    python3 benches/buchner_2d_check.py --per-height 30 --out buchner_2d.csv   # about 2 minutes
    # the settings of wgsph's buchner_p1 case instead of Marrone et al.'s:
    python3 benches/buchner_2d_check.py --tait --clamp --laplacian-alpha 0.05 \
        --artificial-viscosity 0 --sound-speed 14.1421356 --out buchner_2d_case.csv
"""
import argparse
import math
import sys

import numba
import numpy as np

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument('--per-height', type=int, default=30, help='particles over the column height H')
parser.add_argument('--sound-speed', type=float, default=20.0, help='c0 in units of sqrt(g H)')
parser.add_argument('--artificial-viscosity', type=float, default=0.02, help="Monaghan's alpha")
parser.add_argument('--laplacian-alpha', type=float, default=0.0, help='Laplacian viscosity nu = a h c0 / 8')
parser.add_argument('--delta', type=float, default=0.1, help='delta-SPH coefficient')
parser.add_argument('--tait', action='store_true', help='Tait equation of state instead of linear')
parser.add_argument('--clamp', action='store_true', help='clamp negative pressure to zero')
parser.add_argument('--end-time', type=float, default=1.85, help='s (the measured window ends at 1.80 s)')
parser.add_argument('--courant', type=float, default=0.2, help='dt = COURANT h / c0')
parser.add_argument('--out', default='buchner_2d.csv')
args = parser.parse_args()

HEIGHT, WIDTH, LENGTH, GRAVITY, RHO0 = 0.6, 1.2, 3.22, 9.81, 1000.0
WALL_TOP = 2.4
DX = HEIGHT / args.per_height
H = 2.0 * DX
C0 = args.sound_speed * math.sqrt(GRAVITY * HEIGHT)
MASS = RHO0 * DX * DX
NU = args.laplacian_alpha * H * C0 / 8.0
ALPHA = args.artificial_viscosity
DELTA = args.delta
TAIT, CLAMP = args.tait, args.clamp
B_TAIT = RHO0 * C0 * C0 / 7.0
SIGMA = 10.0 / (7.0 * math.pi * H * H)  # cubic spline, 2D
LAYERS = 5
# More than the particles a support of radius 2h = 4 spacings can hold (about 50, more when
# compressed).
NEIGHBOURS_MAX = 256

fluid = np.array([(x, y) for x in np.arange(DX / 2, WIDTH, DX) for y in np.arange(DX / 2, HEIGHT, DX)])
walls = []
for k in range(LAYERS):
    for y in np.arange(-DX / 2 - (LAYERS - 1) * DX, WALL_TOP, DX):
        walls += [(-DX / 2 - k * DX, y), (LENGTH + DX / 2 + k * DX, y)]
    walls += [(x, -DX / 2 - k * DX) for x in np.arange(DX / 2, LENGTH, DX)]
N_FLUID = len(fluid)
pos = np.vstack([fluid, np.array(walls)])
vel = np.zeros_like(pos)
depth_pressure = RHO0 * GRAVITY * (HEIGHT - fluid[:, 1])
rho = np.full(len(pos), RHO0)
rho[:N_FLUID] = RHO0 * (1 + depth_pressure / B_TAIT) ** (1 / 7) if TAIT else RHO0 + depth_pressure / C0**2

CELL = 2 * H
X0 = Y0 = -LAYERS * DX - CELL
NCX = int((LENGTH + LAYERS * DX + CELL - X0) / CELL) + 2
NCY = int((WALL_TOP + CELL - Y0) / CELL) + 2


@numba.njit
def kernel(r):
    q = r / H
    if q < 1.0:
        return SIGMA * (1.0 - 1.5 * q * q + 0.75 * q**3)
    if q < 2.0:
        return SIGMA * 0.25 * (2.0 - q) ** 3
    return 0.0


@numba.njit
def gradient_over_r(r):
    """dW/dr / r, so that grad_i W_ij = gradient_over_r(r) (x_i - x_j)."""
    q = r / H
    if q < 1.0:
        return SIGMA * (-3.0 * q + 2.25 * q * q) / (H * r) if r > 0.0 else 0.0
    if q < 2.0:
        return -0.75 * SIGMA * (2.0 - q) ** 2 / (H * r)
    return 0.0


@numba.njit
def pressure_of(density):
    p = B_TAIT * ((density / RHO0) ** 7 - 1.0) if TAIT else C0 * C0 * (density - RHO0)
    return max(p, 0.0) if CLAMP else p


@numba.njit
def cell_of(x, y):
    cx = min(max(int((x - X0) / CELL), 0), NCX - 1)
    cy = min(max(int((y - Y0) / CELL), 0), NCY - 1)
    return cx, cy


@numba.njit
def within_support(pos, order, start, x, y, found):
    """Writes the indices of the particles closer than 2h to (x, y) into `found`; their number."""
    cx, cy = cell_of(x, y)
    count = 0
    for ix in range(max(cx - 1, 0), min(cx + 2, NCX)):
        for iy in range(max(cy - 1, 0), min(cy + 2, NCY)):
            c = ix * NCY + iy
            for k in range(start[c], start[c + 1]):
                j = order[k]
                if (pos[j, 0] - x) ** 2 + (pos[j, 1] - y) ** 2 < 4.0 * H * H:
                    if count == found.shape[0]:
                        raise ValueError('more neighbours than NEIGHBOURS_MAX')
                    found[count] = j
                    count += 1
    return count


@numba.njit
def bin_particles(pos):
    cells = np.empty(pos.shape[0], np.int64)
    for i in range(pos.shape[0]):
        cx, cy = cell_of(pos[i, 0], pos[i, 1])
        cells[i] = cx * NCY + cy
    order = np.argsort(cells)
    start = np.zeros(NCX * NCY + 1, np.int64)
    for c in cells:
        start[c + 1] += 1
    for c in range(NCX * NCY):
        start[c + 1] += start[c]
    return order, start


@numba.njit
def wall_pressure(pos, rho, p, order, start):
    """Adami, Hu & Adams (2012) Eq. 27 with a wall at rest: the fluid's pressure and weight."""
    found = np.empty(NEIGHBOURS_MAX, np.int64)
    for w in range(N_FLUID, pos.shape[0]):
        weight = 0.0
        summed = 0.0
        for k in range(within_support(pos, order, start, pos[w, 0], pos[w, 1], found)):
            j = found[k]
            if j >= N_FLUID:
                continue
            dy = pos[w, 1] - pos[j, 1]
            wk = kernel(math.hypot(pos[w, 0] - pos[j, 0], dy))
            weight += wk
            summed += (p[j] - GRAVITY * rho[j] * dy) * wk
        p[w] = summed / weight if weight > 0.0 else 0.0
        if TAIT:
            rho[w] = RHO0 * max(1.0 + p[w] / B_TAIT, 1e-3) ** (1.0 / 7.0)
        else:
            rho[w] = RHO0 + p[w] / (C0 * C0)


@numba.njit
def interactions(pos, vel, rho, p, order, start, acceleration, density_rate, forces):
    """The forces (when `forces`) or the density rate of each fluid particle."""
    found = np.empty(NEIGHBOURS_MAX, np.int64)
    for i in range(N_FLUID):
        ax, ay, drho = 0.0, -GRAVITY, 0.0
        for k in range(within_support(pos, order, start, pos[i, 0], pos[i, 1], found)):
            j = found[k]
            if j == i:
                continue
            rx, ry = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1]
            r2 = rx * rx + ry * ry
            f = gradient_over_r(math.sqrt(r2))
            gx, gy = f * rx, f * ry
            fluid_j = j < N_FLUID
            vx = vel[i, 0] - (vel[j, 0] if fluid_j else 0.0)
            vy = vel[i, 1] - (vel[j, 1] if fluid_j else 0.0)
            volume = MASS / rho[j]
            if forces:
                pf = (p[i] + p[j]) / (rho[i] * rho[j])
                ax -= MASS * pf * gx
                ay -= MASS * pf * gy
                if fluid_j:
                    vr = vx * rx + vy * ry
                    if ALPHA > 0.0 and vr < 0.0:
                        # Monaghan (1992): Pi_ij = -alpha c0 mu_ij / rho_ij
                        mu = H * vr / (r2 + 0.01 * H * H)
                        pi_ij = -ALPHA * C0 * mu / (0.5 * (rho[i] + rho[j]))
                        ax -= MASS * pi_ij * gx
                        ay -= MASS * pi_ij * gy
                    if NU > 0.0:
                        # Morris, Fox & Zhu (1997)
                        coef = 2.0 * NU * volume * (rx * gx + ry * gy) / (r2 + 0.01 * H * H)
                        ax += coef * vx
                        ay += coef * vy
            else:
                drho += rho[i] * (vx * gx + vy * gy) * volume
                if fluid_j:
                    # Molteni & Colagrossi (2009), less the hydrostatic difference
                    # rho0 g (y_i - y_j) / c0^2 (Fourtakas et al. 2019)
                    diff = (rho[j] - rho[i]) - RHO0 * GRAVITY * ry / (C0 * C0)
                    drho += DELTA * H * C0 * 2.0 * diff / r2 * (-(rx * gx + ry * gy)) * volume
        if forces:
            acceleration[i, 0] = ax
            acceleration[i, 1] = ay
        else:
            density_rate[i] = drho


@numba.njit
def wall_readings(pos, rho, p, order, start, heights):
    """Shepard-normalised kernel average of the fluid's pressure on the far wall."""
    out = np.zeros(heights.shape[0])
    found = np.empty(NEIGHBOURS_MAX, np.int64)
    for q in range(heights.shape[0]):
        weight = 0.0
        summed = 0.0
        for k in range(within_support(pos, order, start, LENGTH, heights[q], found)):
            j = found[k]
            if j >= N_FLUID:
                continue
            wk = kernel(math.hypot(LENGTH - pos[j, 0], heights[q] - pos[j, 1])) * MASS / rho[j]
            weight += wk
            summed += wk * p[j]
        out[q] = summed / weight if weight > 0.0 else 0.0
    return out


def main():
    dt = args.courant * H / C0
    sample_every = max(1, round(0.0005 / dt))
    heights = np.arange(21) * 0.01
    acceleration = np.zeros((N_FLUID, 2))
    density_rate = np.zeros(N_FLUID)
    p = np.zeros(len(pos))
    rows = []
    print(f'spacing {DX} m, h {H} m, c0 {C0:.2f} m/s, {N_FLUID} fluid and {len(pos) - N_FLUID} wall particles, dt {dt:.3e} s',
          file=sys.stderr)
    step = 0
    while step * dt < args.end_time:
        order, start = bin_particles(pos)
        for i in range(N_FLUID):
            p[i] = pressure_of(rho[i])
        wall_pressure(pos, rho, p, order, start)
        if step % sample_every == 0:
            rows.append(np.r_[step * dt, wall_readings(pos, rho, p, order, start, heights)])
        interactions(pos, vel, rho, p, order, start, acceleration, density_rate, True)
        vel[:N_FLUID] += dt * acceleration
        interactions(pos, vel, rho, p, order, start, acceleration, density_rate, False)
        pos[:N_FLUID] += dt * vel[:N_FLUID]
        rho[:N_FLUID] += dt * density_rate
        step += 1
        speed = np.sqrt((vel[:N_FLUID] ** 2).sum(1)).max()
        if not math.isfinite(speed) or speed > C0:
            sys.exit(f'stopped at t = {step * dt:.3f} s: a particle at {speed:.3g} m/s (c0 = {C0:.3g} m/s)')
    header = 't_s,' + ','.join(f'p_at_{h:.2f}_m_Pa' for h in heights)
    np.savetxt(args.out, np.array(rows), delimiter=',', header=header, comments='')
    print(f'wrote {args.out}: {len(rows)} samples to t = {step * dt:.3f} s', file=sys.stderr)


main()
