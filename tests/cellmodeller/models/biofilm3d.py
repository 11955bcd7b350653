# 3D (jitter_z=True) on a base plane z = 0, in a sphere of radius 6 (cells inside it).
import random

from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=True, gamma=20, max_planes=1, max_spheres=1)
    biophys.addPlane((0, 0, 0), (0, 0, 1), 1.0)
    biophys.addSphere((0, 0, 0), 6, 1.0, -1)
    sim.init(biophys, ModuleRegulator(sim, sim.moduleName), None, None)
    sim.addCell(cellType=0, pos=(0, 0, 0.5))


def init(cell):
    cell.targetVol = 3.0 + random.uniform(0.0, 0.5)
    cell.growthRate = 1.0


def update(cells):
    for (id, cell) in cells.items():
        if cell.volume > cell.targetVol:
            cell.divideFlag = True


def divide(parent, d1, d2):
    d1.targetVol = 3.0 + random.uniform(0.0, 0.5)
    d2.targetVol = 3.0 + random.uniform(0.0, 0.5)
