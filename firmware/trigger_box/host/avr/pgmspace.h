// Host build: the stand-ins are in ../Arduino.h.
#pragma once
#include "../Arduino.h"
