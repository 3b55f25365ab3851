/* Prints the exported controller's structs as the C compiler lays them out, for tests/test_export_controller.py to
   hold against their ctypes mirror: a line "STRUCT MEMBER OFFSET SIZE" (bytes) per member, "STRUCT - 0 SIZE" per
   struct. The test lists the members in struct_members.h as MEMBER(struct, member) and STRUCT(struct) lines. */
#include <stddef.h>
#include <stdio.h>
#include "chewbot_ctrl.h"

#define MEMBER(s, m) printf(#s " " #m " %lu %lu\n", (unsigned long)offsetof(s, m), (unsigned long)sizeof(((s*)0)->m));
#define STRUCT(s) printf(#s " - 0 %lu\n", (unsigned long)sizeof(s));

int main(void) {
#include "struct_members.h"
  return 0;
}
