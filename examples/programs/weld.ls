/PROG  WELD
/ATTR
OWNER		= MNEDITOR;
COMMENT		= "weld seam, table";
PROG_SIZE	= 1024;
CREATE		= DATE 26-01-12  TIME 10:00:00;
MODIFIED	= DATE 26-01-12  TIME 10:00:00;
FILE_NAME	= ;
VERSION		= 0;
LINE_COUNT	= 10;
MEMORY_SIZE	= 1400;
PROTECT		= READ_WRITE;
TCD:  STACK_SIZE	= 0,
      TASK_PRIORITY	= 50,
      TIME_SLICE	= 0,
      BUSY_LAMP_OFF	= 0,
      ABORT_REQUEST	= 0,
      PAUSE_REQUEST	= 0;
DEFAULT_GROUP	= 1,*,*,*,*;
CONTROL_CODE	= 00000000 00000000;
/APPL
/MN
   1:  UFRAME_NUM=1 ;
   2:  UTOOL_NUM=1 ;
   3:J P[7:home] 100% FINE    ;
   4:J P[1] 100% CNT50    ;
   5:L P[2:seam start] 100mm/sec FINE    ;
   6:  !Arc on (was P[2] X = 50.000 mm) ;
   7:L P[3] 20mm/sec CNT100    ;
   8:C P[4]    
    :  P[5] 20mm/sec CNT100    ;
   9:L P[6] 1000mm/sec CNT50    ;
  10:J P[7:home] 100% FINE    ;
/POS
P[1]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =    40.000  mm,	Y =   -40.000  mm,	Z =    60.000  mm,
	W =  -170.000 deg,	P =     0.000 deg,	R =   180.000 deg
};
P[2:"seam start"]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =    50.000  mm,	Y =   -40.000  mm,	Z =     5.000  mm,
	W =  -170.000 deg,	P =     0.000 deg,	R =   180.000 deg
};
P[3]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   110.000  mm,	Y =   -40.000  mm,	Z =     5.000  mm,
	W =  -170.000 deg,	P =     0.000 deg,	R =   180.000 deg
};
P[4]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   150.000  mm,	Y =   -20.000  mm,	Z =     5.000  mm,
	W =  -170.000 deg,	P =     0.000 deg,	R =  -160.000 deg
};
P[5]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   170.000  mm,	Y =    20.000  mm,	Z =     5.000  mm,
	W =  -170.000 deg,	P =     0.000 deg,	R =  -140.000 deg
};
P[6]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'N U T, 0, 0, 0',
	X =   170.000  mm,	Y =    20.000  mm,	Z =   120.000  mm,
	W =  -170.000 deg,	P =     0.000 deg,	R =  -140.000 deg
};
P[7:"home"]{
   GP1:
	UF : 0, UT : 1,	
	J1=     0.000 deg,	J2=     0.000 deg,	J3=     0.000 deg,
	J4=     0.000 deg,	J5=    30.000 deg,	J6=     0.000 deg
};
/END
