/* The reference task compiled in: ${rows} rows of t (s), q, dq, ddq (m, rad; /s; /s^2), F_B (N). */
#include "chewbot_ctrl.h"

const double chewbot_ctrl_task[] = {
${table}
};
