/* Steering-rate step of a linear controller file: see autosteer_step.h.
 *
 * Each block names the line of design/files/linear.py (LinearController) it implements.
 * Comparisons are written as Python's max(a, b) / min(a, b) evaluate them (b if b > a,
 * b if b < a, else a), so NaN passes through the same way.
 */
#include <math.h>

#include "autosteer_step.h"

void as_reset(as_state *s)
{
    int i;
    for (i = 0; i < AS_NC_ALLOC; ++i) {
        s->xc[i] = 0.0;                       /* self._xc = np.zeros(order) */
    }
    s->fresh = 1;                             /* self._fresh = True */
}

double as_step(as_state *s, double cross_track, double heading_error, double wheel_angle, double speed)
{
    const double meas[3] = {cross_track, heading_error, wheel_angle};
    double y[AS_NY];
    double xn[AS_NC_ALLOC];
    double u, ua, t;
    int i, j;

    /* v = max(float(m.speed), self.spec.speed_min) */
    const double v = (AS_SPEED_MIN > speed) ? AS_SPEED_MIN : speed;
    for (i = 0; i < AS_NY; ++i) {
        /* y = [m.<name> / v if normalization == "speed" else m.<name>] */
        y[i] = AS_DIVIDE_BY_SPEED[i] ? meas[AS_MEASUREMENT[i]] / v : meas[AS_MEASUREMENT[i]];
        /* if c is not None: y[i] = min(max(y[i], -c), c) */
        if (AS_HAS_CLIP[i]) {
            t = (-AS_CLIP[i] > y[i]) ? -AS_CLIP[i] : y[i];
            y[i] = (AS_CLIP[i] < t) ? AS_CLIP[i] : t;
        }
    }
    /* if self._fresh: self._xc = X0 @ y; self._fresh = False */
    if (s->fresh) {
        for (i = 0; i < AS_NC; ++i) {
            t = 0.0;
            for (j = 0; j < AS_NY; ++j) {
                t += AS_X0[i * AS_NY + j] * y[j];
            }
            s->xc[i] = t;
        }
        s->fresh = 0;
    }
    /* u = float(self._cc @ self._xc + self._dc @ y) */
    t = 0.0;
    for (i = 0; i < AS_NC; ++i) {
        t += AS_CC[i] * s->xc[i];
    }
    u = 0.0;
    for (j = 0; j < AS_NY; ++j) {
        u += AS_DC[j] * y[j];
    }
    u = t + u;
    /* if not math.isfinite(u): self.reset(); return 0.0 */
    if (!isfinite(u)) {
        as_reset(s);
        return 0.0;
    }
    /* ua = min(max(u, -lim), lim) */
    t = (-AS_RATE_LIMIT > u) ? -AS_RATE_LIMIT : u;
    ua = (AS_RATE_LIMIT < t) ? AS_RATE_LIMIT : t;
    /* self._xc = self._ac @ self._xc + self._bc @ y + self._ec * (ua - u) */
    for (i = 0; i < AS_NC; ++i) {
        double a = 0.0, b = 0.0;
        for (j = 0; j < AS_NC; ++j) {
            a += AS_AC[i * AS_NC + j] * s->xc[j];
        }
        for (j = 0; j < AS_NY; ++j) {
            b += AS_BC[i * AS_NY + j] * y[j];
        }
        xn[i] = a + b + AS_EC[i] * (ua - u);
    }
    for (i = 0; i < AS_NC; ++i) {
        s->xc[i] = xn[i];
    }
    return ua;
}
