/* The kinematic backend's slot, compiled with the mission's rules into one call. */
#include <math.h>

#include "../native.h"

#define PATH_POINTS 5 /* separations are checked at 0.2, 0.4, ..., 1 of each move */

/* Each AUV holds its speed setpoint over the ground along its heading, as the hull's speed
 * servo does (it acts on the surge velocity over the ground), up to the water speed V_max,
 * and drifts with the current's component across its heading (docked AUVs stay); a move that
 * would end outside the area is rejected (the AUV stays). Propulsion energy is the cubic term
 * for the speed through the water (along the heading) over the slot. */
int64_t iout_kinematic_slot(const Mission *m)
{
    int64_t status = iout_check_mission(m, true, false);
    if (status)
        return status;
    const Params *p = m->p;
    const State *s = &m->s;
    int64_t n = m->n_auvs;
    double end[2 * n], heading[n], speed[n], energy_j[n], yaw_j[n], path[PATH_POINTS * 2 * n];
    for (int64_t e = 0; e < m->n_envs; e++) {
        iout_begin_env(m, e);
        double cx = s->current_mps[2 * e], cy = s->current_mps[2 * e + 1];
        for (int64_t i = 0; i < n; i++) {
            int64_t a = e * n + i;
            double x0 = s->positions_m[2 * a], y0 = s->positions_m[2 * a + 1];
            double sx = s->straight_end_m[2 * a], sy = s->straight_end_m[2 * a + 1];
            double hx = cos(s->heading_sp[a]), hy = sin(s->heading_sp[a]);
            double along_mps = cx * hx + cy * hy;
            double ground_mps = fmin(s->speed_sp[a], p->v_max_mps + along_mps);
            double water_mps = fabs(ground_mps - along_mps);
            double drift_s = s->docked[a] ? 0.0 : p->slot_s;
            /* the straight move at the setpoint, corrected to the ground speed, plus the drift
             * across the heading (no current: exactly the straight move) */
            double dx = (ground_mps - s->speed_sp[a]) * hx + (cx - along_mps * hx);
            double dy = (ground_mps - s->speed_sp[a]) * hy + (cy - along_mps * hy);
            double x = sx + dx * drift_s, y = sy + dy * drift_s;
            /* the move through the water: along the heading at ground minus current speed */
            double wx = sx - x0 + (ground_mps - s->speed_sp[a] - along_mps) * hx * drift_s;
            double wy = sy - y0 + (ground_mps - s->speed_sp[a] - along_mps) * hy * drift_s;
            double water_m = s->docked[a] ? 0.0 : hypot(wx, wy);
            if (s->boundary_attempt[a] || !iout_in_area(p, x, y)) {
                x = x0;
                y = y0;
                water_m = 0.0;
            }
            end[2 * i] = x;
            end[2 * i + 1] = y;
            heading[i] = iout_wrap_angle(s->heading_sp[a]);
            speed[i] = s->speed_sp[a];
            energy_j[i] = water_mps > 0.0
                              ? p->drag_power_w_at_1mps * pow(water_mps, 3) * water_m / water_mps
                              : 0.0;
            yaw_j[i] = 0.0;
            for (int64_t f = 0; f < PATH_POINTS; f++) {
                double frac = (double)(f + 1) / PATH_POINTS;
                path[f * 2 * n + 2 * i] = x0 + frac * (x - x0);
                path[f * 2 * n + 2 * i + 1] = y0 + frac * (y - y0);
            }
        }
        iout_end_env(m, e, end, heading, speed, energy_j, yaw_j, path, 2 * n, PATH_POINTS);
    }
    return IOUT_OK;
}
