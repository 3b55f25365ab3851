/* chewbot_ctrl.c: the controller step (hand-written part; the graphs are in chewbot_ctrl_kernels.c). */
#include <math.h>
#include <string.h>
#include "chewbot_ctrl.h"
#include "chewbot_ctrl_kernels.h"

#define NQ CHEWBOT_CTRL_NQ
#define NN CHEWBOT_CTRL_NN
#define COLS CHEWBOT_CTRL_TASK_COLUMNS
#define ROWS CHEWBOT_CTRL_TASK_ROWS

static const double HOME[6] = {${HOME}};
static const double HERMITE[6][6] = {${HERMITE}};
static const double GAINS[CHEWBOT_CTRL_NG] = {${GAINS}};

size_t chewbot_ctrl_size(void) { return sizeof(chewbot_ctrl); }

void chewbot_ctrl_home_angles(double theta[6]) {
  int i;
  for (i = 0; i < 6; ++i) theta[i] = HOME[i];
}

static int is_finite(double x) { return x - x == 0.0; }

/* The task's reference at t: quintic Hermite between the samples (the samples themselves at their times), the bite
   force linear; before the first sample the first, after the last the last with zero rates. ctx->row is a warm start. */
static void task_reference(chewbot_ctrl* ctx, double t, double q[NQ], double dq[NQ], double ddq[NQ], double force[3]) {
  const double* first = chewbot_ctrl_task;
  const double* last = chewbot_ctrl_task + (ROWS - 1) * COLS;
  const double* a;
  const double* b;
  double dt, s, c[6], ends[6], pw[6];
  long i = ctx->row;
  int j, k, m;
  if (ROWS < 2 || !(t >= first[0] && t <= last[0])) { /* outside the table: its nearest end, at rest */
    a = (ROWS < 2 || !(t > first[0])) ? first : last;
    for (j = 0; j < NQ; ++j) { q[j] = a[1 + j]; dq[j] = 0.0; ddq[j] = 0.0; }
    for (j = 0; j < 3; ++j) force[j] = a[1 + 3 * NQ + j];
    return;
  }
  while (i > 0 && chewbot_ctrl_task[i * COLS] > t) --i;
  while (i < ROWS - 2 && chewbot_ctrl_task[(i + 1) * COLS] <= t) ++i;
  ctx->row = i;
  a = chewbot_ctrl_task + i * COLS;
  b = a + COLS;
  dt = b[0] - a[0];
  s = (t - a[0]) / dt;
  pw[0] = 1.0;
  for (k = 1; k < 6; ++k) pw[k] = pw[k - 1] * s;
  for (j = 0; j < NQ; ++j) {
    double p = 0.0, dp = 0.0, ddp = 0.0;
    ends[0] = a[1 + j]; ends[1] = dt * a[1 + NQ + j]; ends[2] = dt * dt * a[1 + 2 * NQ + j];
    ends[3] = b[1 + j]; ends[4] = dt * b[1 + NQ + j]; ends[5] = dt * dt * b[1 + 2 * NQ + j];
    for (k = 0; k < 6; ++k) {
      c[k] = 0.0;
      for (m = 0; m < 6; ++m) c[k] += HERMITE[k][m] * ends[m];
    }
    for (k = 0; k < 6; ++k) p += c[k] * pw[k];
    for (k = 1; k < 6; ++k) dp += c[k] * k * pw[k - 1];
    for (k = 2; k < 6; ++k) ddp += c[k] * (k * (k - 1)) * pw[k - 2];
    q[j] = p; dq[j] = dp / dt; ddq[j] = ddp / (dt * dt);
  }
  for (j = 0; j < 3; ++j) force[j] = a[1 + 3 * NQ + j] + (t - a[0]) * ((b[1 + 3 * NQ + j] - a[1 + 3 * NQ + j]) / dt);
}

static void reference_at(chewbot_ctrl* ctx, double t, double q[NQ], double dq[NQ], double ddq[NQ], double force[3]) {
  int j;
  if (!ctx->user_reference) { task_reference(ctx, t, q, dq, ddq, force); return; }
  for (j = 0; j < NQ; ++j) { q[j] = ctx->user_q_ref[j]; dq[j] = ctx->user_dq_ref[j]; ddq[j] = ctx->user_ddq_ref[j]; }
  for (j = 0; j < 3; ++j) force[j] = ctx->user_force[j];
}

void chewbot_ctrl_init(chewbot_ctrl* ctx, double t0, const double offsets[6]) {
  double ddq[NQ], force[3];
  int i;
  memset(ctx, 0, sizeof *ctx);
  for (i = 0; i < CHEWBOT_CTRL_NG; ++i) ctx->config.gains[i] = GAINS[i];
  ctx->config.cutoff_hz = ${CUTOFF};
  ctx->config.torque_limit = ${TORQUE_LIMIT};
  ctx->config.torque_rate_limit = ${RATE_LIMIT};
  ctx->config.watchdog_s = ${WATCHDOG};
  ctx->config.fk_step_tolerance = ${FK_STEP};
  ctx->config.fk_residual_tolerance = ${FK_RESIDUAL};
  ctx->config.conditioning_min = ${CONDITIONING};
  ctx->config.transmission_min = ${TRANSMISSION};
  ctx->config.distribution_step_tolerance = ${DIST_STEP};
  ctx->config.max_hold_ticks = ${MAX_HOLD};
  ctx->config.gear_ratio = ${DRIVE_GEAR_RATIO};
  ctx->config.gear_efficiency = ${DRIVE_GEAR_EFFICIENCY};
  ctx->config.torque_constant = ${DRIVE_TORQUE_CONSTANT};
  ctx->config.encoder_counts = ${DRIVE_ENCODER_COUNTS};
  for (i = 0; i < 6; ++i) ctx->offsets[i] = offsets ? offsets[i] : 0.0;
  reference_at(ctx, t0, ctx->q, ctx->dq, ddq, force);
  for (i = 0; i < NQ; ++i) ctx->held_q_ref[i] = ctx->q[i];
  ctx->t_estimate = t0;
  ctx->t_last = t0;
}

void chewbot_ctrl_home(chewbot_ctrl* ctx, const double theta_raw_at_home[6]) {
  int i;
  for (i = 0; i < 6; ++i) ctx->offsets[i] = theta_raw_at_home[i] - HOME[i];
}

void chewbot_ctrl_set_reference(chewbot_ctrl* ctx, const double q_ref[NQ], const double dq_ref[NQ], const double ddq_ref[NQ],
                                const double force[3]) {
  int j;
  for (j = 0; j < NQ; ++j) { ctx->user_q_ref[j] = q_ref[j]; ctx->user_dq_ref[j] = dq_ref[j]; ctx->user_ddq_ref[j] = ddq_ref[j]; }
  for (j = 0; j < 3; ++j) ctx->user_force[j] = force[j];
  ctx->user_reference = 1;
}

void chewbot_ctrl_use_task(chewbot_ctrl* ctx) { ctx->user_reference = 0; }
void chewbot_ctrl_set_estop(chewbot_ctrl* ctx, int on) { ctx->estop = on != 0; }
void chewbot_ctrl_clear_faults(chewbot_ctrl* ctx) { ctx->latched = 0; ctx->hold_ticks = 0; }

static void fk(chewbot_ctrl* ctx, const double theta[6], const double guess[NQ]) {
  chewbot_ctrl_outputs* o = &ctx->out;
  ctx->arg[0] = theta; ctx->arg[1] = guess;
  ctx->res[0] = o->q; ctx->res[1] = o->pose; ctx->res[2] = &o->fk_residual; ctx->res[3] = &o->fk_step;
  ctx->res[4] = &o->conditioning; ctx->res[5] = &o->transmission; ctx->res[6] = &o->pose_margin;
  chewbot_ctrl_fk(ctx->arg, ctx->res, ctx->iw, ctx->w, 0);
}

/* The motors' torques and currents of the output torques at the crank rates, through the drive's loss law inverted. */
static void drive(chewbot_ctrl* ctx) {
  chewbot_ctrl_outputs* o = &ctx->out;
  double numbers[3];
  numbers[0] = ctx->config.gear_ratio; numbers[1] = ctx->config.gear_efficiency; numbers[2] = ctx->config.torque_constant;
  ctx->arg[0] = o->tau; ctx->arg[1] = o->dtheta; ctx->arg[2] = numbers;
  ctx->res[0] = o->tau_motor; ctx->res[1] = o->current;
  chewbot_ctrl_drive(ctx->arg, ctx->res, ctx->iw, ctx->w, 0);
}

static void law(chewbot_ctrl* ctx) {
  chewbot_ctrl_outputs* o = &ctx->out;
  ctx->arg[0] = o->q; ctx->arg[1] = o->dq; ctx->arg[2] = o->q_ref; ctx->arg[3] = o->dq_ref; ctx->arg[4] = o->ddq_ref;
  ctx->arg[5] = o->force; ctx->arg[6] = ctx->config.gains;
  ctx->res[0] = o->tau_cmd; ctx->res[1] = o->normal; ctx->res[2] = &o->ref_margin; ctx->res[3] = &o->dist_step;
  ctx->res[4] = &o->limit_excess;
  chewbot_ctrl_law(ctx->arg, ctx->res, ctx->iw, ctx->w, 0);
}

unsigned chewbot_ctrl_step(chewbot_ctrl* ctx, double t, const double theta_measured[6], double tau_out[6], unsigned* status_out) {
  chewbot_ctrl_outputs* o = &ctx->out;
  double theta[6], guess[NQ];
  unsigned status = 0;
  int i, usable = 1, bad_time = 0;
  double dt = t - ctx->t_last;
  if (!is_finite(t) || (ctx->started && !(dt >= 0.0))) { status |= CHEWBOT_CTRL_BAD_INPUT; bad_time = 1; dt = 0.0; }
  if (ctx->started && dt > ctx->config.watchdog_s) ctx->latched |= CHEWBOT_CTRL_WATCHDOG;
  o->dt = dt;
  /* the pose estimate: Gauss-Newton from the last one */
  for (i = 0; i < 6; ++i) {
    theta[i] = theta_measured[i] - ctx->offsets[i];
    if (!is_finite(theta[i])) status |= CHEWBOT_CTRL_BAD_INPUT;
  }
  for (i = 0; i < NQ; ++i) guess[i] = ctx->q[i];
  if (!(status & CHEWBOT_CTRL_BAD_INPUT)) {
    /* the crank rates, which the drive's loss law takes the power's direction from: the filtered difference */
    if (ctx->angles_known && dt > 0.0) {
      double bf = exp(-2.0 * 3.14159265358979323846 * ctx->config.cutoff_hz * dt);
      for (i = 0; i < 6; ++i) ctx->dtheta[i] = bf * ctx->dtheta[i] + (1.0 - bf) * (theta[i] - ctx->theta_last[i]) / dt;
    }
    for (i = 0; i < 6; ++i) ctx->theta_last[i] = theta[i];
    ctx->angles_known = 1;
    fk(ctx, theta, guess);
    if (!(o->fk_step <= ctx->config.fk_step_tolerance && o->fk_residual <= ctx->config.fk_residual_tolerance))
      status |= CHEWBOT_CTRL_FK_NOT_CONVERGED;
    if (!(o->conditioning >= ctx->config.conditioning_min && o->transmission >= ctx->config.transmission_min))
      status |= CHEWBOT_CTRL_NEAR_SINGULAR;
    for (i = 0; i < NQ; ++i) if (!is_finite(o->q[i])) status |= CHEWBOT_CTRL_FK_NOT_CONVERGED;
  }
  usable = !(status & (CHEWBOT_CTRL_BAD_INPUT | CHEWBOT_CTRL_FK_NOT_CONVERGED | CHEWBOT_CTRL_NEAR_SINGULAR));
  if (usable) {
    /* the rates: the filtered backward difference of the estimates */
    double de = t - ctx->t_estimate;
    if (de > 0.0) {
      double bf = exp(-2.0 * 3.14159265358979323846 * ctx->config.cutoff_hz * de);
      for (i = 0; i < NQ; ++i) ctx->dq[i] = bf * ctx->dq[i] + (1.0 - bf) * (o->q[i] - ctx->q[i]) / de;
    }
    for (i = 0; i < NQ; ++i) ctx->q[i] = o->q[i];
    ctx->t_estimate = t;
  }
  for (i = 0; i < NQ; ++i) { o->q[i] = ctx->q[i]; o->dq[i] = ctx->dq[i]; }
  /* the reference and the law; a reference outside the workspace: hold the last one inside, at rest */
  reference_at(ctx, t, o->q_ref, o->dq_ref, o->ddq_ref, o->force);
  law(ctx);
  if (!(o->ref_margin > 0.0)) {
    double asked = o->ref_margin; /* reported: the margin of the reference asked for */
    status |= CHEWBOT_CTRL_REFERENCE_OUTSIDE;
    for (i = 0; i < NQ; ++i) { o->q_ref[i] = ctx->held_q_ref[i]; o->dq_ref[i] = 0.0; o->ddq_ref[i] = 0.0; }
    law(ctx);
    o->ref_margin = asked;
  } else {
    for (i = 0; i < NQ; ++i) ctx->held_q_ref[i] = o->q_ref[i];
  }
  for (i = 0; i < NQ; ++i) o->error[i] = o->q_ref[i] - o->q[i];
  for (i = 0; i < 6; ++i) if (!is_finite(o->tau_cmd[i])) usable = 0;
  if (o->limit_excess > 0.0) status |= CHEWBOT_CTRL_LIMIT_ACTIVE;
  if (!(o->dist_step <= ctx->config.distribution_step_tolerance)) status |= CHEWBOT_CTRL_DISTRIBUTION_NOT_CONVERGED;
  /* the torques */
  if (ctx->estop || (ctx->latched & CHEWBOT_CTRL_WATCHDOG)) {
    for (i = 0; i < 6; ++i) o->tau[i] = 0.0;
    if (ctx->estop) status |= CHEWBOT_CTRL_ESTOP;
  } else {
    if (usable) {
      ctx->hold_ticks = 0;
      for (i = 0; i < 6; ++i) {
        double lim = ctx->config.torque_limit, v = o->tau_cmd[i];
        if (v > lim || v < -lim) { status |= CHEWBOT_CTRL_TORQUE_SATURATED; v = v > lim ? lim : -lim; }
        o->tau[i] = v;
      }
    } else {
      status |= CHEWBOT_CTRL_HOLDING;
      ctx->hold_ticks += 1;
      for (i = 0; i < 6; ++i) o->tau[i] = ctx->hold_ticks <= ctx->config.max_hold_ticks ? ctx->tau_last[i] : 0.0;
    }
    if (ctx->config.torque_rate_limit > 0.0) {
      double step = ctx->config.torque_rate_limit * dt;
      for (i = 0; i < 6; ++i) {
        double d = o->tau[i] - ctx->tau_last[i];
        if (d > step || d < -step) { status |= CHEWBOT_CTRL_RATE_LIMITED; o->tau[i] = ctx->tau_last[i] + (d > 0 ? step : -step); }
      }
    }
  }
  status |= ctx->latched;
  for (i = 0; i < 6; ++i) { tau_out[i] = o->tau[i]; ctx->tau_last[i] = o->tau[i]; o->dtheta[i] = ctx->dtheta[i]; }
  drive(ctx);
  if (!bad_time) ctx->t_last = t;
  ctx->started = 1;
  ctx->ticks += 1;
  if (status_out) *status_out = status;
  return status;
}

unsigned chewbot_ctrl_step_counts(chewbot_ctrl* ctx, double t, const long counts[6], double current_out[6], unsigned* status_out) {
  double theta[6], tau[6];
  double rad_per_count = 2.0 * 3.14159265358979323846 / (ctx->config.encoder_counts * ctx->config.gear_ratio);
  unsigned status;
  int i;
  for (i = 0; i < 6; ++i) theta[i] = rad_per_count > 0.0 && is_finite(rad_per_count) ? (double)counts[i] * rad_per_count : NAN;
  status = chewbot_ctrl_step(ctx, t, theta, tau, status_out);
  for (i = 0; i < 6; ++i) current_out[i] = ctx->out.current[i];
  return status;
}
