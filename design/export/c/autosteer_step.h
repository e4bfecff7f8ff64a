/* Steering-rate step of a linear controller file (design export --format c).
 *
 * Dependency-free C99 (only <math.h> for isfinite). The numbers come from
 * controller_data.h, which `design export --format c` writes from the controller
 * file; this file and autosteer_step.c are the same for every controller.
 * The step is the one of design/files/linear.py (LinearController.step); see
 * docs/controller_export.md for the two side by side.
 */
#ifndef AUTOSTEER_STEP_H
#define AUTOSTEER_STEP_H

#include "controller_data.h"

typedef struct {
    double xc[AS_NC_ALLOC]; /* compensator state */
    int fresh;              /* 1 until the first step after a reset (bumpless engage) */
} as_state;

/* Forget the state (call on every engage, as the loop calls Controller.reset). */
void as_reset(as_state *s);

/* One cycle: measured cross-track [m, + left], heading error [rad, + CCW], wheel angle
 * [rad, + left], ground speed [m/s] -> steering-rate command [rad/s, + left], already
 * clipped to +-AS_RATE_LIMIT. A non-finite command resets the state and returns 0. */
double as_step(as_state *s, double cross_track, double heading_error, double wheel_angle, double speed);

#endif /* AUTOSTEER_STEP_H */
