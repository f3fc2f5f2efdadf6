/* Builds the C half of the test programs' shared precompiled header (common/test_pch.h). */
