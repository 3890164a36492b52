#pragma once
/// \file
/// Every component, for code that needs all of them (loaders, writers, the editor).

#include "scene/components/animation.h"
#include "scene/components/camera.h"
#include "scene/components/kinematics.h"
#include "scene/components/light.h"
#include "scene/components/material.h"
#include "scene/components/mesh.h"
#include "scene/components/name.h"
#include "scene/components/parent.h"
#include "scene/components/ray_cache_cube.h"
#include "scene/components/transform.h"
#include "scene/components/world_transform.h"
