/* Planar added mass of an AUV hull: a MuJoCo passive-force plugin, "iout.added_mass".

   The hull moves on world-axis joints x, y (slides) and a yaw hinge, so its MuJoCo inertia is
   isotropic in the plane. The body's mass already carries the surge added mass -X_udot and its
   I_zz the yaw added inertia -N_rdot (exact, in MuJoCo's own dynamics). This plugin applies the
   rest of the body-frame added mass (Fossen 2011, eqs. 6.43ff; Prestero 2001, Ch. 3):

     M_A = [[-X_udot, 0, 0], [0, -Y_vdot, -Y_rdot], [0, -N_vdot, -N_rdot]],  N_vdot = Y_rdot,

   the anisotropic part [[0, 0, 0], [0, D, c], [0, c, 0]] with D = X_udot - Y_vdot, c = -Y_rdot,
   both as -M_A nu_dot and as its Coriolis-centripetal (Munk) terms -C_A(nu_r) nu_r, in the
   water-relative body velocity nu_r = (u, v, r) (MuJoCo's wind is the current). Axes: x forward,
   y to port, z up; in these axes C_A of the residual mass gives
     X = D v r + c r^2,  Y = 0,  N = -D u v - c u r.

   The acceleration: with the hull's other forces F_o (thrust, fluid drag and lift, rudder,
   joint limits), the true dynamics are M nu_dot = F_o + K(nu) (K: the rigid-body and added-mass
   Coriolis terms), with M = M_B + the residual mass and M_B = diag(m_b, m_b, I_b) the body's
   MuJoCo inertia. The plugin applies F_p = M_B nu_dot - (MuJoCo's own rigid-body terms) - F_o,
   so that MuJoCo's M_B nu_dot = F_o + F_p + ... follows the true dynamics. F_o is not known when
   passive forces are computed (actuators come later), so it is recovered after each substep
   from the velocity change the substep made, F_o = M_B dqvel/dt - F_p - (joint-limit forces),
   and used at the next
   substep: exact as dt -> 0 (one substep of lag after a force step), and F_p never feeds back
   on itself. The velocity terms use the current velocity. F_o lives in mjData's plugin state,
   so mj_getState/mj_setState (and mujoco.rollout) carry it.

   Optionally it also applies hull forces MuJoCo's ellipsoid model lacks, in the same axes and
   water-relative velocity: Y = yvv v|v| + yrr r|r| + yuv u v, N = nvv v|v| + nuv u v (cross-flow
   drag and body lift, as in Prestero's equations); these are known when the plugin runs, so
   they enter the acceleration solve at once, and F_o holds only the forces of others.

   Configured per instance (MJCF <extension><plugin><instance>): body, the hull body's name;
   xudot, yvdot, yrdot: X_udot, Y_vdot (kg), Y_rdot = N_vdot (kg m); optional (0 if absent):
   yvv (kg/m), yrr (kg m/rad^2), nvv (kg), yuv (kg/m), nuv (kg).
   Requires: the body's joints x (slide along world x), y (slide along world y), yaw (hinge
   about world z), in this order; its centre of mass on the hinge axis and principal axes
   aligned with the body; no armature on these dofs. */

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include <mujoco/mujoco.h>

#define PLUGIN_NAME "iout.added_mass"

static const char* const ATTRIBUTES[] = {"body", "xudot", "yvdot", "yrdot", "yvv",
                                         "yrr",  "nvv",   "yuv",   "nuv"};
enum {
  ATTR_BODY,
  ATTR_XUDOT,
  ATTR_YVDOT,
  ATTR_YRDOT,
  ATTR_YVV,  /* the optional hull terms: 0 when absent */
  ATTR_YRR,
  ATTR_NVV,
  ATTR_YUV,
  ATTR_NUV,
  NATTRIBUTE
};

/* Plugin state per instance: F_o carried to the next substep, and this substep's record. */
enum {
  S_FO = 0,    /* F_o of the last substep in body axes: surge, sway (N), yaw moment (N m) */
  S_FP = 3,    /* F_p applied this substep, world axes: x, y (N), yaw (N m) */
  S_QVEL = 6,  /* qvel of x, y, yaw when F_p was computed */
  S_YAW = 9,   /* yaw when F_p was computed */
  NSTATE = 10
};

typedef struct {
  int dof[3];     /* dof addresses of x, y, yaw */
  int qpos_yaw;   /* qpos address of yaw */
  mjtNum mass;    /* m_b: rigid mass - X_udot (the body's mass) */
  mjtNum inertia; /* I_b: rigid I_zz - N_rdot (the body's I_zz) */
  mjtNum sway;    /* D = X_udot - Y_vdot: sway added mass beyond the surge's */
  mjtNum couple;  /* c = -Y_rdot = -N_vdot */
  mjtNum yvv, yrr, nvv, yuv, nuv; /* the hull's cross-flow drag and lift */
} Hull;

static int nstate(const mjModel* m, int instance) { return NSTATE; }

static int read_attribute(const mjModel* m, int instance, int attr, mjtNum* out) {
  const char* text = mj_getPluginConfig(m, instance, ATTRIBUTES[attr]);
  char* end = NULL;
  if ((!text || !*text) && attr >= ATTR_YVV) {
    *out = 0;
    return 0;
  }
  if (!text || !*text) {
    mju_warning(PLUGIN_NAME ": config '%s' is missing (accepted: body, the hull body's name; "
                "xudot, yvdot, yrdot in kg, kg, kg m)", ATTRIBUTES[attr]);
    return -1;
  }
  *out = strtod(text, &end);
  if (*end != '\0' || !isfinite(*out)) {
    mju_warning(PLUGIN_NAME ": config '%s' = '%s' is not a number", ATTRIBUTES[attr], text);
    return -1;
  }
  return 0;
}

static int is_axis(const mjtNum* axis, int k) {
  for (int i = 0; i < 3; i++) {
    if (fabs(axis[i] - (i == k)) > 1e-9) return 0;
  }
  return 1;
}

/* The body named in the config, with the joints and inertia the plugin requires. */
static int find_hull(const mjModel* m, int instance, Hull* hull) {
  const char* name = mj_getPluginConfig(m, instance, ATTRIBUTES[ATTR_BODY]);
  int body = name ? mj_name2id(m, mjOBJ_BODY, name) : -1;
  if (body < 1) {
    mju_warning(PLUGIN_NAME ": config body = '%s' names no body (accepted: the name of the "
                "hull's body)", name ? name : "");
    return -1;
  }
  static const int types[3] = {mjJNT_SLIDE, mjJNT_SLIDE, mjJNT_HINGE};
  static const int axes[3] = {0, 1, 2};
  int adr = m->body_jntadr[body];
  if (m->body_jntnum[body] != 3) {
    mju_warning(PLUGIN_NAME ": body %d needs joints x, y, yaw (has %d joints)", body,
                m->body_jntnum[body]);
    return -1;
  }
  for (int j = 0; j < 3; j++) {
    int jnt = adr + j, dof = m->jnt_dofadr[jnt];
    if (m->jnt_type[jnt] != types[j] || !is_axis(m->jnt_axis + 3 * jnt, axes[j]) ||
        m->dof_armature[dof] != 0) {
      mju_warning(PLUGIN_NAME ": body %d's joints must be slide x, slide y, hinge z, in this "
                  "order, without armature", body);
      return -1;
    }
    hull->dof[j] = dof;
  }
  const mjtNum* ipos = m->body_ipos + 3 * body;
  const mjtNum* iquat = m->body_iquat + 4 * body;
  if (fabs(ipos[0]) + fabs(ipos[1]) > 1e-12 || fabs(fabs(iquat[0]) - 1) > 1e-12 ||
      m->jnt_pos[3 * (adr + 2)] != 0 || m->jnt_pos[3 * (adr + 2) + 1] != 0) {
    mju_warning(PLUGIN_NAME ": body %d's centre of mass must lie on the yaw axis, with its "
                "principal axes along the body's", body);
    return -1;
  }
  hull->qpos_yaw = m->jnt_qposadr[adr + 2];
  hull->mass = m->body_mass[body];
  hull->inertia = m->body_inertia[3 * body + 2];
  return 0;
}

static int init(const mjModel* m, mjData* d, int instance) {
  mjtNum coef[NATTRIBUTE];
  Hull* hull = malloc(sizeof(Hull));
  if (!hull) return -1;
  for (int a = ATTR_XUDOT; a < NATTRIBUTE; a++) {
    if (read_attribute(m, instance, a, coef + a)) {
      free(hull);
      return -1;
    }
  }
  if (find_hull(m, instance, hull)) {
    free(hull);
    return -1;
  }
  hull->sway = coef[ATTR_XUDOT] - coef[ATTR_YVDOT];
  hull->couple = -coef[ATTR_YRDOT];
  hull->yvv = coef[ATTR_YVV];
  hull->yrr = coef[ATTR_YRR];
  hull->nvv = coef[ATTR_NVV];
  hull->yuv = coef[ATTR_YUV];
  hull->nuv = coef[ATTR_NUV];
  mjtNum det = (hull->mass + hull->sway) * hull->inertia - hull->couple * hull->couple;
  if (hull->mass + hull->sway <= 0 || det <= 0) {
    mju_warning(PLUGIN_NAME ": the planar mass matrix is not positive definite (mass %g kg, "
                "sway added %g kg, I_zz %g kg m^2, coupling %g kg m)", hull->mass, hull->sway,
                hull->inertia, hull->couple);
    free(hull);
    return -1;
  }
  d->plugin_data[instance] = (uintptr_t)hull;
  return 0;
}

static void destroy(mjData* d, int instance) {
  free((Hull*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

static void copy(mjData* dest, const mjModel* m, const mjData* src, int instance) {
  Hull* hull = malloc(sizeof(Hull));
  if (!hull) mju_error(PLUGIN_NAME ": out of memory");
  *hull = *(const Hull*)src->plugin_data[instance];
  dest->plugin_data[instance] = (uintptr_t)hull;
}

static void reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {
  mju_zero(plugin_state, NSTATE);
}

static void compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  const Hull* h = (const Hull*)d->plugin_data[instance];
  mjtNum* s = d->plugin_state + m->plugin_stateadr[instance];
  const mjtNum* qvel = d->qvel;
  mjtNum yaw = d->qpos[h->qpos_yaw], cy = cos(yaw), sy = sin(yaw);
  mjtNum vx = qvel[h->dof[0]] - m->opt.wind[0], vy = qvel[h->dof[1]] - m->opt.wind[1];
  mjtNum u = cy * vx + sy * vy, v = -sy * vx + cy * vy, r = qvel[h->dof[2]];
  mjtNum mb = h->mass, ib = h->inertia, dm = h->sway, c = h->couple;

  /* the hull's own sway force and yaw moment (P's Y_vv, Y_rr, N_vv; body lift Y_uv, N_uv) */
  mjtNum hv = h->yvv * v * fabs(v) + h->yrr * r * fabs(r) + h->yuv * u * v;
  mjtNum hr = h->nvv * v * fabs(v) + h->nuv * u * v;

  /* sway and yaw: (M nu_dot)_{v,r} = g, solved for nu_dot; surge needs no solve */
  mjtNum gv = s[S_FO + 1] + hv - mb * r * u;
  mjtNum gr = s[S_FO + 2] + hr - dm * u * v - c * u * r;
  mjtNum det = (mb + dm) * ib - c * c;
  mjtNum vdot = (ib * gv - c * gr) / det;
  mjtNum rdot = ((mb + dm) * gr - c * gv) / det;
  mjtNum fu = dm * v * r + c * r * r;
  mjtNum fv = mb * vdot - gv + hv;
  mjtNum fr = ib * rdot - s[S_FO + 2];

  mjtNum fx = cy * fu - sy * fv, fy = sy * fu + cy * fv;
  d->qfrc_passive[h->dof[0]] += fx;
  d->qfrc_passive[h->dof[1]] += fy;
  d->qfrc_passive[h->dof[2]] += fr;
  s[S_FP + 0] = fx;
  s[S_FP + 1] = fy;
  s[S_FP + 2] = fr;
  for (int j = 0; j < 3; j++) s[S_QVEL + j] = qvel[h->dof[j]];
  s[S_YAW] = yaw;
}

/* After the substep: the hull's other forces, from the velocity change they made, less the
   joint limits' (a limit is a fence, not a force the hull's fluid mass would follow; lagged by a
   substep, it would also feed back on itself). */
static void advance(const mjModel* m, mjData* d, int instance) {
  const Hull* h = (const Hull*)d->plugin_data[instance];
  mjtNum* s = d->plugin_state + m->plugin_stateadr[instance];
  mjtNum rate = 1 / m->opt.timestep;
  const mjtNum* limit = d->qfrc_constraint;  /* the arena's fence: it acts on M_B alone */
  mjtNum fx = h->mass * (d->qvel[h->dof[0]] - s[S_QVEL + 0]) * rate - s[S_FP + 0];
  mjtNum fy = h->mass * (d->qvel[h->dof[1]] - s[S_QVEL + 1]) * rate - s[S_FP + 1];
  mjtNum fr = h->inertia * (d->qvel[h->dof[2]] - s[S_QVEL + 2]) * rate - s[S_FP + 2];
  fx -= limit[h->dof[0]];
  fy -= limit[h->dof[1]];
  fr -= limit[h->dof[2]];
  mjtNum cy = cos(s[S_YAW]), sy = sin(s[S_YAW]);
  s[S_FO + 0] = cy * fx + sy * fy;
  s[S_FO + 1] = -sy * fx + cy * fy;
  s[S_FO + 2] = fr;
}

mjPLUGIN_LIB_INIT(iout_added_mass) {
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = PLUGIN_NAME;
  plugin.capabilityflags = mjPLUGIN_PASSIVE;
  plugin.nattribute = NATTRIBUTE;
  plugin.attributes = ATTRIBUTES;
  plugin.nstate = nstate;
  plugin.init = init;
  plugin.destroy = destroy;
  plugin.copy = copy;
  plugin.reset = reset;
  plugin.compute = compute;
  plugin.advance = advance;
  mjp_registerPlugin(&plugin);
}
