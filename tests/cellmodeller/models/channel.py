# A 2D colony between two planes 6 µm apart (a channel along x).
import random

from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=False, max_planes=2, gamma=100)
    biophys.addPlane((0, -3, 0), (0, 1, 0), 1)
    biophys.addPlane((0, 3, 0), (0, -1, 0), 1)
    sim.init(biophys, ModuleRegulator(sim, sim.moduleName), None, None)
    sim.addCell(cellType=0, pos=(0, 0, 0), dir=(1, 0, 0))


def init(cell):
    cell.targetVol = 2.5 + random.uniform(0.0, 0.5)
    cell.growthRate = 2.0


def update(cells):
    for (id, cell) in cells.items():
        if cell.volume > cell.targetVol:
            cell.divideFlag = True


def divide(parent, d1, d2):
    d1.targetVol = 2.5 + random.uniform(0.0, 0.5)
    d2.targetVol = 2.5 + random.uniform(0.0, 0.5)
