#pragma once
/// \file
/// Every component, for code that needs all of them (loaders, writers, the editor).

#include "specula/scene/components/animation.h"
#include "specula/scene/components/camera.h"
#include "specula/scene/components/kinematics.h"
#include "specula/scene/components/light.h"
#include "specula/scene/components/material.h"
#include "specula/scene/components/mesh.h"
#include "specula/scene/components/name.h"
#include "specula/scene/components/parent.h"
#include "specula/scene/components/ray_cache_cube.h"
#include "specula/scene/components/transform.h"
#include "specula/scene/components/world_transform.h"
