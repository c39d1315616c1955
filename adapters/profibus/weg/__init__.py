"""WEG CFW-11, CFW700 and CFW320 on Profibus DP: device profiles and simulated devices.

Sources: the WEG Profibus DP manuals in the seeds (CFW-11 in Portuguese, CFW700 and CFW320
in English). Every bit and scale cites its table or section; choices where the manuals are
silent are written down in docs/devices.md ("WEG CFW-11 / CFW700 / CFW320").

Modules:

* :mod:`.spec` - what differs between the three models, as data (addresses, telegram
  parameters, status-word bits, fault and alarm texts, P0740 states);
* :mod:`.words` - the cyclic words of both data profiles and the speed scales;
* :mod:`.options` - the profile's keys of a drive's config table;
* :mod:`.records` - parameter access over DP-V1 records 47 (PROFIdrive) and 48 (WEG);
* :mod:`.scales` - the speed word's base and the ratings it comes from;
* :mod:`.dataprofile`, :mod:`.manufacturer`, :mod:`.profidrive` - the two data profiles
  (P0741) as strategies: control, status and speed words;
* :mod:`.mapped` - the telegram's mapped input words (P0742..);
* :mod:`.programming` - the drive's programming checked at connect (P0741, mapping);
* :mod:`.profile` - the :class:`~adapters.profibus.contract.DpProfile` shared by the models;
* :mod:`.cfw11`, :mod:`.cfw700`, :mod:`.cfw320` - the registered profile classes;
* :mod:`.sim` - the simulated drives (:mod:`.sim.drive`), split the same way.
"""
