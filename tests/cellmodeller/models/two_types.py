# Two cell types placed 20 µm apart, coloured by type (as CellModeller's ex1a_simpleGrowth2Types).
import random

from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.GUI import Renderers
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=False)
    regul = ModuleRegulator(sim)
    sim.init(biophys, regul, None, None)
    sim.addCell(cellType=0, pos=(-10, 0, 0))
    sim.addCell(cellType=1, pos=(10, 0, 0))
    sim.addRenderer(Renderers.GLBacteriumRenderer(sim))
    sim.pickleSteps = 10


def init(cell):
    cell.targetVol = 2.5 + random.uniform(0.0, 0.5)
    cell.growthRate = 2.0 if cell.cellType == 0 else 1.0


def update(cells):
    for (id, cell) in cells.items():
        cell.color = [cell.cellType * 0.6 + 0.1, 1.0 - cell.cellType * 0.6, 0.3]
        if cell.volume > cell.targetVol:
            cell.divideFlag = True


def divide(parent, d1, d2):
    d1.targetVol = 2.5 + random.uniform(0.0, 0.5)
    d2.targetVol = 2.5 + random.uniform(0.0, 0.5)
