// libmrcal is a C library; its headers carry no extern "C" of their own.
#pragma once
extern "C" {
#include <mrcal/mrcal.h>
}
