/* The C half of the test programs' precompiled header: CMake wants one for each language of a program that
   reuses it, and the test programs have no C code of their own. */
#include <stddef.h>
