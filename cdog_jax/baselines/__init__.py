from ._greedy import GreedyOptions as GreedyOptions, greedy_groups as greedy_groups
from ._components import ComponentsOptions as ComponentsOptions, components_groups as components_groups
from ._voting import VotingOptions as VotingOptions, voting_groups as voting_groups
