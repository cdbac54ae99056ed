#!/usr/bin/env python3
"""Prints the block store a scene file names, as a path: the scene's "store" key, resolved
against the scene file's folder (as raystack resolves it). Used by the bench scripts.

    tools/bench/scene_store.py SCENE.json
"""
import json
import os
import sys

scene = sys.argv[1]
with open(scene) as f:
    store = json.load(f)["store"]
print(os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(scene)), store)))
